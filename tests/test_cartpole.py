"""Cart-pole: determinism, state round trip, failure, and textbook accelerations."""

import math

import mujoco
import numpy as np
import pytest

from tatl_mj import suite
from tatl_mj.suite import cartpole


def _episode(seed: int, action_indices: np.ndarray) -> np.ndarray:
    env = suite.load("cartpole", "balance", task_kwargs={"random": seed})
    observations = [env.reset().observation["state"]]
    for i in action_indices:
        timestep = env.step(cartpole.ACTIONS[i])
        observations.append(timestep.observation["state"])
        if timestep.last():
            break
    return np.array(observations)


def test_same_seed_and_actions_give_identical_observations():
    actions = np.random.default_rng(1).integers(0, 3, size=60)
    first, second = _episode(7, actions), _episode(7, actions)
    np.testing.assert_array_equal(first, second)
    assert not np.array_equal(first[0], _episode(8, actions)[0])


def test_start_state_is_uniform_within_005():
    starts = np.array([_episode(seed, np.array([], int))[0] for seed in range(20)])
    assert np.all(np.abs(starts) <= 0.05)
    assert starts.std() > 0.01  # really drawn, not a constant


def test_state_round_trip():
    physics = cartpole.balance(random=0).physics
    state = np.array([0.3, -1.2, 0.1, 2.5])
    physics.set_state_vector(state)
    np.testing.assert_array_equal(physics.state_vector(), state)
    assert physics.cart_position() == 0.3 and physics.pole_angular_velocity() == 2.5
    batch = np.random.default_rng(0).normal(size=(5, 4))
    np.testing.assert_array_equal(physics.states_from(*physics.qpos_qvel_from(batch)), batch)


def test_uncontrolled_pole_falls_and_terminates():
    env = cartpole.balance(random=0)
    env.reset()
    env.physics.set_state_vector([0.0, 0.0, 0.02, 0.0])
    rewards = []
    for _ in range(200):
        timestep = env.step(cartpole.ACTIONS[1])
        rewards.append(timestep.reward)
        if timestep.last():
            break
    assert timestep.last() and timestep.discount == 0.0
    assert env.physics.pole_angle() > cartpole.THETA_LIMIT  # fell towards +x, as tilted
    assert rewards[-1] == 0.0 and all(r == 1.0 for r in rewards[:-1])
    # From 0.02 rad, theta grows ~cosh(t sqrt(g / l_eff)); 12 degrees takes about 0.6 s.
    assert 15 <= len(rewards) <= 60


def test_cart_leaving_the_rail_terminates():
    env = cartpole.balance(random=0)
    env.reset()
    env.physics.set_state_vector([2.39, 1.0, 0.0, 0.0])
    timestep = env.step(cartpole.ACTIONS[1])
    assert timestep.last() and timestep.discount == 0.0 and timestep.reward == 0.0


def test_time_limit_is_not_a_failure():
    env = cartpole.balance(time_limit=0.1, random=0)
    env.reset()
    env.physics.set_state_vector(np.zeros(4))
    steps = [env.step(cartpole.ACTIONS[1]) for _ in range(5)]
    assert steps[-1].last() and steps[-1].discount == 1.0 and steps[-1].reward == 1.0


@pytest.mark.parametrize(
    "params",
    [cartpole.CartPoleParams(), cartpole.CartPoleParams(cart_mass=2.5, pole_mass=0.4, pole_half_length=0.8)],
)
@pytest.mark.parametrize("force", [20.0, -7.0])
def test_initial_accelerations_match_textbook_equations(params, force):
    env = cartpole.balance(random=0, params=params)
    physics = env.physics
    model = physics.model
    # The MJCF's actual mass properties, read back from the compiled model.
    big_m = model.body_mass[model.name2id("cart", "body")]
    pole = model.name2id("pole", "body")
    m, l, inertia = model.body_mass[pole], model.body_ipos[pole][2], model.body_inertia[pole][1]
    g = -model.opt.gravity[2]
    assert (big_m, m, l, g) == pytest.approx(
        (params.cart_mass, params.pole_mass, params.pole_half_length, params.gravity)
    )

    physics.set_state_vector(np.zeros(4))
    physics.set_control([force])
    mujoco.mj_forward(model.ptr, physics.data.ptr)
    x_dd, theta_dd = physics.data.qacc

    # Lagrange's equations at theta = 0, theta_dot = 0:
    #   (M + m) x_dd + m l theta_dd = F,   m l x_dd + (I + m l^2) theta_dd = 0.
    lhs = np.array([[big_m + m, m * l], [m * l, inertia + m * l * l]])
    expected = np.linalg.solve(lhs, [force, 0.0])
    np.testing.assert_allclose([x_dd, theta_dd], expected, rtol=0.01)
    # Gymnasium's closed form (uniform rod, I = m l^2 / 3) gives the same numbers.
    total = big_m + m
    gym_theta_dd = -(force / total) / (l * (4.0 / 3.0 - m / total))
    assert theta_dd == pytest.approx(gym_theta_dd, rel=0.01)
    assert theta_dd * force < 0  # pushing the cart +x tips the pole towards -x


def test_tilted_pole_accelerates_under_gravity():
    physics = cartpole.balance(random=0).physics
    theta = 0.1
    physics.set_state_vector([0.0, 0.0, theta, 0.0])
    mujoco.mj_forward(physics.model.ptr, physics.data.ptr)
    m, l, big_m, g = 0.1, 0.5, 1.0, 9.8
    total = big_m + m
    # Gymnasium's equations with F = 0 and theta_dot = 0.
    expected = g * math.sin(theta) / (l * (4.0 / 3.0 - m * math.cos(theta) ** 2 / total))
    assert physics.data.qacc[1] == pytest.approx(expected, rel=0.01)


def test_force_limit_clips_the_actuator():
    env = cartpole.balance(random=0, params=cartpole.CartPoleParams(force_limit=5.0))
    env.reset()
    env.step(cartpole.ACTIONS[2])
    assert env.physics.cart_force() == pytest.approx(5.0)


@pytest.mark.parametrize("field", ["cart_mass", "pole_mass", "pole_half_length", "gravity", "force_limit"])
@pytest.mark.parametrize("value", [0.0, -1.0, float("nan")])
def test_non_physical_params_raise_naming_the_field(field, value):
    with pytest.raises(ValueError, match=f"CartPoleParams.{field}"):
        cartpole.CartPoleParams(**{field: value})


def test_wrong_params_type_raises():
    with pytest.raises(ValueError, match="params"):
        cartpole.balance(params={"cart_mass": 1.0})


def test_actions_and_spec():
    env = suite.load("cartpole", "balance")
    np.testing.assert_array_equal(cartpole.ACTIONS, [[-20.0], [0.0], [20.0]])
    spec = env.action_spec()
    assert spec.shape == (1,) and spec.minimum[0] == -20.0 and spec.maximum[0] == 20.0
    assert env.control_timestep() == pytest.approx(0.02)
    assert env.observation_spec()["state"].shape == (4,)
