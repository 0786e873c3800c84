"""Pendulum: measured periods, refreshed dynamics after edits, the time-varying schedule,
the flipped control, under-actuation, determinism and parameter checks."""

import math

import mujoco
import numpy as np
import pytest

from tatl_mj import suite
from tatl_mj.suite import pendulum

G = 9.81


def _measured_period(physics: pendulum.Physics, seconds: float) -> float:
    """Free small oscillation about hanging down; period from interpolated zero crossings."""
    physics.set_state_vector([math.pi - 0.05, 0.0])
    physics.set_control([0.0])
    n = int(round(seconds / physics.model.opt.timestep))
    deviation = np.empty(n + 1)
    deviation[0] = physics.data.qpos[0] - math.pi
    for i in range(n):
        mujoco.mj_step(physics.model.ptr, physics.data.ptr)
        deviation[i + 1] = physics.data.qpos[0] - math.pi
    times = np.arange(n + 1) * physics.model.opt.timestep
    k = np.nonzero(np.sign(deviation[:-1]) != np.sign(deviation[1:]))[0]
    crossings = times[k] - deviation[k] * (times[k + 1] - times[k]) / (deviation[k + 1] - deviation[k])
    assert len(crossings) >= 4, "too few half-periods to measure"
    return 2.0 * float(np.mean(np.diff(crossings)))


def test_small_oscillation_period_scales_as_sqrt_length():
    physics = pendulum.make_physics()
    lengths = (0.5, 1.0, 1.5)
    periods = []
    for length in lengths:
        physics.set_pendulum(length, 1.0)
        periods.append(_measured_period(physics, seconds=8.0))
    for length, period in zip(lengths, periods):
        assert period == pytest.approx(2 * math.pi * math.sqrt(length / G), rel=0.02)
        assert period / periods[1] == pytest.approx(math.sqrt(length), rel=0.02)
    assert periods[0] < periods[1] < periods[2]  # the edit really changed the dynamics


@pytest.mark.parametrize("length, mass, torque", [(1.2, 0.6, 2.0), (0.7, 1.8, -1.5)])
def test_mass_and_length_edit_changes_angular_acceleration(length, mass, torque):
    physics = pendulum.make_physics()
    theta = math.pi / 2  # horizontal, towards +x: gravity pulls theta up

    def angular_acceleration() -> float:
        physics.set_state_vector([theta, 0.0])
        physics.set_control([torque])
        mujoco.mj_forward(physics.model.ptr, physics.data.ptr)
        return float(physics.data.qacc[0])

    before = angular_acceleration()
    assert before == pytest.approx((G * 1.0 * math.sin(theta) + torque) / 1.0, rel=0.005)
    physics.set_pendulum(length, mass)
    after = angular_acceleration()
    # Point mass m at L: (m L^2) theta_dd = m g L sin(theta) + u (tip inertia is < 0.3 %).
    expected = (mass * G * length * math.sin(theta) + torque) / (mass * length**2)
    assert after == pytest.approx(expected, rel=0.005)
    assert abs(after - before) > 0.05 * abs(before)
    # Derived fields were recomputed by mj_setConst, not only the raw ones written.
    assert physics.named.model.body_subtreemass["pole"] == pytest.approx(mass)
    assert physics.pendulum_length() == length and physics.pendulum_mass() == mass


def test_set_pendulum_leaves_the_live_state_untouched():
    physics = pendulum.make_physics()
    physics.set_state_vector([2.0, -1.3])
    physics.data.time = 4.2
    before = {name: getattr(physics.data, name).copy() for name in ("qpos", "qvel", "ctrl")}
    physics.set_pendulum(1.4, 0.8)
    for name, value in before.items():
        np.testing.assert_array_equal(getattr(physics.data, name), value)
    assert physics.data.time == 4.2
    # Derived quantities (qacc, positions) are the new model's: set_pendulum ends with forward().
    forwarded = physics.data.qacc.copy()
    physics.forward()
    np.testing.assert_array_equal(physics.data.qacc, forwarded)


def test_timevarying_follows_schedule_and_state_is_continuous():
    env = suite.load("pendulum", "swingup_timevarying", task_kwargs={"random": 3})
    env.reset()
    physics = env.physics
    assert physics.pendulum_length() == 1.5 and physics.pendulum_mass() == 1.5
    reference = pendulum.make_physics()  # a second model, edited by hand
    actions = np.random.default_rng(0).integers(0, 3, size=150)
    n_sub = round(pendulum.CONTROL_TIMESTEP / physics.model.opt.timestep)
    for i, a in enumerate(actions):
        qpos, qvel = physics.data.qpos.copy(), physics.data.qvel.copy()
        timestep = env.step(pendulum.ACTIONS[a])
        wave = 0.5 * math.cos(math.pi * i / 50)
        assert physics.pendulum_length() == 1.0 + wave
        assert physics.pendulum_mass() == 1.0 + wave
        # Same edit, then the step from the unchanged previous state: identical result.
        reference.set_pendulum(1.0 + wave, 1.0 + wave)
        reference.data.qpos[:], reference.data.qvel[:] = qpos, qvel
        reference.data.ctrl[:] = pendulum.ACTIONS[a]
        mujoco.mj_step(reference.model.ptr, reference.data.ptr, nstep=n_sub)
        np.testing.assert_array_equal(timestep.observation["state"], reference.state_vector())
    assert env.task.rollout_compatible is False
    env.reset()  # a new episode starts from L_0, M_0 again
    assert physics.pendulum_length() == 1.5 and physics.pendulum_mass() == 1.5


def test_flipped_control_is_the_exact_negative():
    normal = suite.load("pendulum", "swingup", task_kwargs={"random": 11})
    flipped = suite.load("pendulum", "swingup_flipped", task_kwargs={"random": 11})
    np.testing.assert_array_equal(normal.reset().observation["state"], flipped.reset().observation["state"])
    for i in np.random.default_rng(2).integers(0, 3, size=100):
        # ACTIONS is symmetric: index 2 - i is the negative of index i.
        s_normal = normal.step(pendulum.ACTIONS[2 - i]).observation["state"]
        s_flipped = flipped.step(pendulum.ACTIONS[i]).observation["state"]
        np.testing.assert_array_equal(s_normal, s_flipped)
    # Same action from the same state: opposite torques, so different motions.
    normal.physics.set_state_vector([3.0, 0.0])
    flipped.physics.set_state_vector([3.0, 0.0])
    a = normal.step(pendulum.ACTIONS[2]).observation["state"]
    b = flipped.step(pendulum.ACTIONS[2]).observation["state"]
    assert a[1] > b[1]


def _run(env, policy) -> np.ndarray:
    states = [env.reset().observation["state"]]
    timestep = None
    while timestep is None or not timestep.last():
        timestep = env.step(policy(states[-1]))
        states.append(timestep.observation["state"])
    return np.array(states)


@pytest.mark.parametrize("index", [0, 2])
def test_constant_full_torque_never_gets_above_horizontal(index):
    states = _run(pendulum.swingup(random=0), lambda s: pendulum.ACTIONS[index])
    assert len(states) == 201
    # It only oscillates about the tilted equilibrium asin(2 / 9.81) from hanging.
    assert np.min(np.abs(states[:, 0])) > math.pi / 2
    assert np.min(np.abs(states[:, 0])) < math.pi - 0.3  # but it does move


def test_energy_pumping_reaches_upright_and_holds():
    m, length = 1.0, 1.0
    inertia = m * length**2 + 0.4 * m * pendulum.TIP_RADIUS**2
    top = m * G * length  # energy at rest upright

    def pump_then_catch(state: np.ndarray) -> np.ndarray:
        theta, theta_dot = state
        if abs(theta) < 0.5:  # near the top: bang-bang PD with a dead band
            u = -(30.0 * theta + 8.0 * theta_dot)
            return pendulum.ACTIONS[2] if u > 1 else pendulum.ACTIONS[0] if u < -1 else pendulum.ACTIONS[1]
        energy = 0.5 * inertia * theta_dot**2 + m * G * length * math.cos(theta)
        if energy >= top:
            return pendulum.ACTIONS[1]
        return pendulum.ACTIONS[2] if theta_dot >= 0 else pendulum.ACTIONS[0]  # push along the motion

    for seed in (0, 1):
        states = _run(pendulum.swingup(random=seed), pump_then_catch)
        assert np.abs(states[:, 0]).min() < 0.1
        last_two_seconds = states[-40:]
        assert np.abs(last_two_seconds[:, 0]).max() < 0.1
        rewards = pendulum.Task(pendulum.PendulumParams()).batch_reward(last_two_seconds)
        assert rewards.min() > -1.0


@pytest.mark.parametrize("task", sorted(pendulum.TASKS))
def test_determinism(task):
    def episode(seed):
        env = suite.load("pendulum", task, task_kwargs={"random": seed, "time_limit": 2.0})
        actions = np.random.default_rng(5).integers(0, 3, size=40)
        return np.array(
            [env.reset().observation["state"]] + [env.step(pendulum.ACTIONS[a]).observation["state"] for a in actions]
        )

    first = episode(4)
    np.testing.assert_array_equal(first, episode(4))
    assert not np.array_equal(first[0], episode(5)[0])


def test_start_state_hangs_down_with_small_perturbation():
    for seed in range(10):
        theta, theta_dot = pendulum.swingup(random=seed).reset().observation["state"]
        assert math.pi - abs(theta) <= 0.05 and abs(theta_dot) <= 0.05


def test_state_round_trip_and_wrapping():
    physics = pendulum.make_physics()
    physics.set_state_vector([2.5, -3.0])
    np.testing.assert_array_equal(physics.state_vector(), [2.5, -3.0])
    states = physics.states_from(np.array([[2 * math.pi + 0.1], [-math.pi - 0.2]]), np.zeros((2, 1)))
    np.testing.assert_allclose(states[:, 0], [0.1, math.pi - 0.2], atol=1e-12)


def test_reward_is_the_papers():
    task = pendulum.Task(pendulum.PendulumParams())
    states = np.array([[0.0, 0.0], [math.pi, 0.0], [0.5, -2.0]])
    np.testing.assert_allclose(task.batch_reward(states), [0.0, -10 * math.pi**2, -2.5 - 20.0])


def test_params_are_applied():
    params = pendulum.PendulumParams(mass=0.7, length=1.3, max_torque=1.0, gravity=5.0)
    env = pendulum.swingup(random=0, params=params)
    physics = env.physics
    assert physics.pendulum_length() == 1.3 and physics.pendulum_mass() == 0.7
    assert physics.model.opt.gravity[2] == -5.0
    env.reset()
    env.step(pendulum.ACTIONS[2])
    assert physics.torque() == pytest.approx(1.0)  # clipped to max_torque


@pytest.mark.parametrize("field", ["mass", "length", "max_torque", "gravity"])
@pytest.mark.parametrize("value", [0.0, -2.0, float("inf")])
def test_non_physical_params_raise_naming_the_field(field, value):
    with pytest.raises(ValueError, match=f"PendulumParams.{field}"):
        pendulum.PendulumParams(**{field: value})


def test_bad_edits_and_options_raise():
    physics = pendulum.make_physics()
    with pytest.raises(ValueError, match="length"):
        physics.set_pendulum(-1.0, 1.0)
    with pytest.raises(ValueError, match="mass"):
        physics.set_pendulum(1.0, float("nan"))
    with pytest.raises(ValueError, match="PendulumParams.length"):
        pendulum.swingup_timevarying(params=pendulum.PendulumParams(length=0.4))
    with pytest.raises(ValueError, match="params"):
        pendulum.swingup(params={"mass": 1.0})


def test_actions_spec_and_rollout_flags():
    np.testing.assert_array_equal(pendulum.ACTIONS, [[-4.0], [0.0], [4.0]])
    for task in pendulum.TASKS:
        env = suite.load("pendulum", task)
        assert env.control_timestep() == pytest.approx(0.05)
        assert env.observation_spec()["state"].shape == (2,)
        assert env.task.rollout_compatible is (task != "swingup_timevarying")


def test_flipped_gain_scales_the_torque_a_control_gives():
    """From rest at hanging gravity exerts no torque: the first step's speed change is the
    control's, opposite in sign to the plain swing-up's and proportional to the gain."""
    from tatl_mj import suite

    changes = {}
    for task, gain in (("swingup", None), ("swingup_flipped", 1.0), ("swingup_flipped", 0.5)):
        kwargs = {"random": 0} if gain is None else {"random": 0, "gain": gain}
        env = suite.load("pendulum", task, task_kwargs=kwargs)
        env.reset()
        env.physics.set_state_vector(np.array([np.pi, 0.0]))
        changes[(task, gain)] = env.step(np.array([2.0])).observation["state"][1]
    assert changes[("swingup_flipped", 1.0)] == pytest.approx(-changes[("swingup", None)], rel=1e-9)
    assert changes[("swingup_flipped", 0.5)] == pytest.approx(0.5 * changes[("swingup_flipped", 1.0)], rel=0.02)
    with pytest.raises(ValueError, match="gain must be a number > 0, got 0.0"):
        suite.load("pendulum", "swingup_flipped", task_kwargs={"gain": 0.0})


def test_timevarying_amplitude_sets_the_schedule_and_zero_is_the_plain_pendulum():
    assert pendulum.timevarying_schedule(0, amplitude=0.2) == pytest.approx((1.2, 1.2))
    assert pendulum.timevarying_schedule(50, amplitude=0.2) == pytest.approx((0.8, 0.8))
    plain = suite.load("pendulum", "swingup", task_kwargs={"random": 3})
    still = suite.load("pendulum", "swingup_timevarying", task_kwargs={"random": 3, "amplitude": 0.0})
    a, b = plain.reset(), still.reset()
    np.testing.assert_array_equal(a.observation["state"], b.observation["state"])
    for u in (4.0, -4.0, 0.0, 4.0):
        np.testing.assert_allclose(
            plain.step(np.array([u])).observation["state"], still.step(np.array([u])).observation["state"], rtol=1e-12
        )
    with pytest.raises(ValueError, match="must exceed the amplitude 1.0"):
        suite.load("pendulum", "swingup_timevarying", task_kwargs={"amplitude": 1.0})
