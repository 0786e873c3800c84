"""Mountain car: the car rides the classic hill, obeys the bead-on-curve equation,
conserves energy, and the task is the classic one (full throttle fails, pumping wins)."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from tatl_mj.suite import mountain_car as mc

DT = mc.CONTROL_TIMESTEP


@pytest.fixture(scope="module")
def env():
    return mc.climb(random=0, time_limit=1000.0)


def _run(env, start, policy, n_steps):
    """Steps from ``start`` with ``policy(state) -> throttle``; returns the states and
    (height offset, energy, work of the force) after every step, and the last timestep."""
    env.reset()
    physics = env.physics
    physics.set_state_vector(start)
    force = float(physics.named.model.actuator_gear["throttle", 0])
    states, offsets, energies, work = [], [], [], [0.0]
    energy0 = physics.mechanical_energy()
    timestep = None
    for _ in range(n_steps):
        throttle = policy(physics.state_vector())
        x_before = physics.position()
        timestep = env.step([throttle])
        states.append(timestep.observation["state"].copy())
        offsets.append(physics.height() - mc.hill_height(physics.position()) - physics.wheel_radius())
        energies.append(physics.mechanical_energy())
        work.append(work[-1] + throttle * force * (physics.position() - x_before))
        if timestep.last():
            break
    return np.array(states), np.array(offsets), energy0, np.array(energies), np.array(work[1:]), timestep


def _pump(state):
    return 1.0 if state[1] >= 0 else -1.0


def test_params_validate_and_reach_the_model():
    with pytest.raises(ValueError, match="car_mass"):
        mc.MountainCarParams(car_mass=0.0)
    with pytest.raises(ValueError, match="damping"):
        mc.MountainCarParams(damping=-1.0)
    with pytest.raises(ValueError, match="force"):
        mc.MountainCarParams(force=float("nan"))
    with pytest.raises(ValueError, match="MountainCarParams"):
        mc.climb(params={"car_mass": 2.0})
    params = mc.MountainCarParams(car_mass=2.0, force=7.0, gravity=9.0, damping=0.3)
    physics = mc.climb(params=params).physics
    assert physics.car_mass() == pytest.approx(2.0)
    assert physics.named.model.actuator_gear["throttle", 0] == pytest.approx(7.0)
    assert physics.model.opt.gravity[2] == pytest.approx(-9.0)
    assert physics.named.model.dof_damping["x"] == pytest.approx(0.3)


def test_state_round_trip_and_velocity_units(env):
    env.reset()
    physics = env.physics
    for state in ([-1.1, 0.03], [-0.52, -0.065], [0.45, 0.01]):
        physics.set_state_vector(state)
        np.testing.assert_allclose(physics.state_vector(), state, rtol=0, atol=1e-12)
        assert physics.velocity() * mc.VELOCITY_SCALE == pytest.approx(state[1])
        # On the surface, moving along it.
        assert physics.height() == pytest.approx(mc.hill_height(state[0]) + physics.wheel_radius())
    states = np.array([[-1.2, 0.0], [-0.3, 0.05], [0.5, -0.07]])
    qpos, qvel = physics.qpos_qvel_from(states)
    np.testing.assert_allclose(physics.states_from(qpos, qvel), states, atol=1e-15)
    with pytest.raises(ValueError, match="shape"):
        physics.set_state_vector([0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="state x must be in"):
        physics.set_state_vector([-2.0, 0.0])


def test_start_state_is_classic():
    xs = []
    for seed in range(20):
        state = mc.climb(random=seed).reset().observation["state"]
        assert state[1] == 0.0
        xs.append(state[0])
    assert min(xs) >= -0.6 and max(xs) <= -0.4
    assert len(set(xs)) == 20


def test_matches_bead_on_curve_equation(env):
    """x(t) from MuJoCo against m(1+h'^2) x'' + m h' h'' x'^2 = F - m g h' solved by scipy."""
    physics = env.physics
    g = -physics.model.opt.gravity[2]
    force_per_mass = physics.named.model.actuator_gear["throttle", 0] / physics.car_mass()

    def bead(t, y, throttle):
        x, x_dot = y
        slope, curvature = mc.hill_slope(x), mc.hill_curvature(x)
        x_ddot = (throttle * force_per_mass - g * slope - slope * curvature * x_dot**2) / (1 + slope**2)
        return [x_dot, x_ddot]

    n = 100
    times = DT * np.arange(1, n + 1)
    for x0, throttle in [(-1.0, 0.0), (-0.5, 1.0), (-0.3, -1.0)]:
        states, *_ = _run(env, [x0, 0.0], lambda s, u=throttle: u, n)
        solution = solve_ivp(bead, (0.0, times[-1]), [x0, 0.0], args=(throttle,), t_eval=times, rtol=1e-10, atol=1e-12)
        assert np.ptp(states[:, 0]) > 0.2  # a real swing, not a car at rest
        np.testing.assert_allclose(states[:, 0], solution.y[0], atol=2e-3)
        np.testing.assert_allclose(states[:, 1], solution.y[1] * DT, atol=5e-4)


def test_free_rolling_conserves_energy_on_the_surface(env):
    states, offsets, energy0, energies, _, _ = _run(env, [-1.0, 0.0], lambda s: 0.0, int(10.0 / DT))
    physics = env.physics
    mass, g = physics.car_mass(), -physics.model.opt.gravity[2]
    bottom = mass * g * (0.1 + physics.wheel_radius())
    swing = energy0 - bottom  # energy above the valley floor, about 3.8 J
    assert np.max(np.abs(energies - energy0)) < 0.005 * swing
    assert np.max(np.abs(offsets)) < 1e-3  # wheel centre within 1 mm of h(x) + r
    assert states[:, 0].min() < -0.95 and states[:, 0].max() > -0.1  # it kept swinging for 10 s


def test_damping_dissipates_energy():
    env = mc.climb(random=0, time_limit=100.0, params=mc.MountainCarParams(damping=0.5))
    _, _, energy0, energies, _, _ = _run(env, [-1.0, 0.0], lambda s: 0.0, 300)
    assert energies[-1] < 0.8 * energy0


def test_full_throttle_alone_fails():
    env = mc.climb(random=0)
    n_steps = int(round(mc.DEFAULT_TIME_LIMIT / DT))
    for x0 in (-0.6, -0.5, -0.4):
        states, _, _, _, _, timestep = _run(env, [x0, 0.0], lambda s: 1.0, n_steps)
        assert len(states) == n_steps and timestep.discount == 1.0  # ran into the time limit
        assert states[:, 0].max() < -0.1  # stalls on the right slope, far below the goal


def test_energy_pumping_reaches_the_goal_and_obeys_work_energy():
    env = mc.climb(random=0)
    n_steps = int(round(mc.DEFAULT_TIME_LIMIT / DT))
    balances_checked = 0
    for x0 in (-0.6, -0.5, -0.4):
        states, offsets, energy0, energies, work, timestep = _run(env, [x0, 0.0], _pump, n_steps)
        assert timestep.last() and timestep.discount == 0.0
        assert states[-1, 0] >= mc.GOAL_X and len(states) < n_steps
        assert timestep.reward == pytest.approx(-((states[-1, 0] - mc.GOAL_X) ** 2))
        assert np.max(np.abs(states[:, 1])) <= mc.V_MAX
        assert np.max(np.abs(offsets)) < 1e-3  # the guide holds it on the track near the crest
        if states[:, 0].min() > mc.X_MIN + 0.02:  # never touched the (lossy) wall
            np.testing.assert_allclose(energies - energy0, work, atol=0.01 * np.abs(work).max())
            balances_checked += 1
    assert balances_checked >= 2


def test_wall_stops_the_car(env):
    states, offsets, *_ = _run(env, [-0.6, -0.06], lambda s: -1.0, 150)
    # The wall is a soft joint limit evaluated once per 14 ms step: it gives up to
    # about 3.3 cm here (the heightfield version, at 2 ms steps, gave 4.5 mm).
    assert states[:, 0].min() > mc.X_MIN - 0.035
    assert states[:, 0].min() < mc.X_MIN + 0.01
    assert np.max(np.abs(offsets)) < 1e-3
    assert states[-1, 0] > mc.X_MIN  # rolled back down, not through


def test_deterministic():
    runs = []
    for _ in range(2):
        env = mc.climb(random=3)
        timestep = env.reset()
        trace = [timestep.observation["state"]]
        for i in range(60):
            trace.append(env.step(mc.ACTIONS[i % 3]).observation["state"])
        runs.append(np.array(trace))
    np.testing.assert_array_equal(runs[0], runs[1])
