"""Bicycle domain: geometry, the benchmark's stability window, control, rider noise."""

import copy
import inspect
import math

import mujoco
import mujoco.rollout
import numpy as np
import pytest

from tatl_mj import suite
from tatl_mj.suite import bicycle, bicycle_stability

# Meijaard et al. (2007), eq. (A 2)-(A 5): the benchmark's linearised equations
# M q'' + v C1 q' + (g K0 + v^2 K2) q = f for q = [roll, steer] (their signs).
BENCH_M = np.array([[80.81722, 2.31941332208709], [2.31941332208709, 0.29784188199686]])
BENCH_C1 = np.array([[0.0, 33.86641391492494], [-0.85035641456978, 1.68540397397560]])
BENCH_K0 = np.array([[-80.95, -2.59951685249872], [-2.59951685249872, -0.80329488458618]])
BENCH_K2 = np.array([[0.0, 76.59734589573222], [0.0, 2.65431523794604]])
BENCH_WEAVE_SPEED = 4.292382  # m/s
BENCH_CAPSIZE_SPEED = 6.024262  # m/s


def benchmark_eigenvalues(speed: float) -> np.ndarray:
    inv = np.linalg.inv(BENCH_M)
    a = np.block(
        [
            [np.zeros((2, 2)), np.eye(2)],
            [-inv @ (9.81 * BENCH_K0 + speed**2 * BENCH_K2), -inv @ (speed * BENCH_C1)],
        ]
    )
    return np.linalg.eigvals(a)


def make_env(**kwargs):
    kwargs.setdefault("random", 0)
    return suite.load("bicycle", "balance", task_kwargs=kwargs)


def run(env, policy, seconds):
    """Steps ``policy(state) -> torque`` for up to ``seconds``; returns (roll trace, last timestep)."""
    timestep = env.reset()
    rolls = [timestep.observation["state"][2]]
    for _ in range(int(round(seconds / bicycle.CONTROL_TIMESTEP))):
        timestep = env.step([policy(timestep.observation["state"])])
        rolls.append(timestep.observation["state"][2])
        if timestep.last():
            break
    return np.array(rolls), timestep


def steer_into_fall(state, discrete=False):
    """Steer towards the lean (roll and roll rate), against the steer angle and rate.

    On the benchmark's linearised equations at 2.778 m/s the closed loop's slowest
    eigenvalues are -2.7 +- 1.0i 1/s. (The earlier gains 20, 5, -20, -1 left a
    real mode at +0.039 1/s: a slow drift into a fall after 25-40 s without noise.)
    """
    steer, steer_rate, roll, roll_rate = state
    torque = 40.0 * roll + 10.0 * roll_rate - 20.0 * steer - 1.0 * steer_rate
    if discrete:  # the paper's {-2, 0, +2} N m
        return bicycle.ACTIONS[1 + int(np.sign(torque)) * (abs(torque) > 1.0), 0]
    return float(np.clip(torque, -2.0, 2.0))


# --- Specs and validation -------------------------------------------------------


def test_specs_and_actions():
    env = make_env()
    spec = env.action_spec()
    assert spec.shape == (1,) and spec.minimum[0] == -2.0 and spec.maximum[0] == 2.0
    np.testing.assert_array_equal(bicycle.ACTIONS, [[-2.0], [0.0], [2.0]])
    timestep = env.reset()
    assert timestep.observation["state"].shape == (4,)
    for action in bicycle.ACTIONS:
        timestep = env.step(action)
        assert np.all(np.isfinite(timestep.observation["state"]))
    assert env.physics.steer_torque() == 2.0


def test_same_seed_same_episode():
    a, b = make_env(random=7), make_env(random=7)
    for env in (a, b):
        env.reset()
    for _ in range(50):
        sa, sb = a.step([0.5]).observation["state"], b.step([0.5]).observation["state"]
        np.testing.assert_array_equal(sa, sb)
    assert not np.array_equal(make_env(random=8).reset().observation["state"], a.reset().observation["state"])


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"speed": 0.0}, "speed"),
        ({"speed": float("nan")}, "speed"),
        ({"cg_noise": -0.01}, "cg_noise"),
        ({"cg_noise": 0.5}, "cg_noise"),
    ],
)
def test_bad_task_kwargs(kwargs, field):
    with pytest.raises(ValueError, match=field):
        make_env(**kwargs)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"rider_mass": 85.0}, "rider_mass"),
        ({"tyre_half_width": 0.0}, "tyre_half_width"),
        ({"tyre_friction": -1.0}, "tyre_friction"),
        ({"gravity": float("inf")}, "gravity"),
        ({"rider_mass": 0.0}, "rider_mass"),
    ],
)
def test_bad_params(kwargs, field):
    with pytest.raises(ValueError, match=field):
        bicycle.BicycleParams(**kwargs)


def test_params_must_be_dataclass():
    with pytest.raises(ValueError, match="BicycleParams"):
        bicycle.model_xml({"rider_mass": 50})


def test_default_params_reproduce_the_xml():
    """model_xml(BicycleParams()) compiles to the same masses, inertias and gears as the file."""
    plain = mujoco.MjModel.from_xml_string(*bicycle.model_xml())
    edited = mujoco.MjModel.from_xml_string(*bicycle.model_xml(bicycle.BicycleParams()))
    for field in (
        "body_mass",
        "body_inertia",
        "body_ipos",
        "actuator_gainprm",
        "actuator_biasprm",
        "actuator_gear",
        "site_pos",
        "geom_size",
        "geom_friction",
        "opt.gravity",
    ):
        get = (lambda m: m.opt.gravity) if field == "opt.gravity" else (lambda m, f=field: getattr(m, f))
        np.testing.assert_allclose(get(edited), get(plain), rtol=1e-6, err_msg=field)
    # The split rear body keeps the benchmark's 85 kg at (0.3, 0, 0.9) above the rear contact.
    data = mujoco.MjData(plain)
    mujoco.mj_forward(plain, data)
    frame, rider = plain.body("frame").id, plain.body("rider").id
    assert plain.body_mass[frame] + plain.body_mass[rider] == pytest.approx(85.0)
    np.testing.assert_allclose(data.xipos[frame], [0.3, 0.0, 0.9], atol=1e-12)
    np.testing.assert_allclose(data.xipos[rider], [0.3, 0.0, 0.9], atol=1e-12)
    assert plain.body_subtreemass[frame] == pytest.approx(94.0)
    # The rider is welded to the frame: the CG noise moves nothing.
    assert plain.body_jntnum[rider] == 0 and plain.nq == 7 + 3
    # The couple's forces: m g / 2L per metre of offset, L either side of the rider's centre of mass.
    for name, sign in (("cg_left", -1.0), ("cg_right", 1.0)):
        np.testing.assert_allclose(plain.actuator(name).gear, [0, 0, sign * 60.0 * 9.81 / 1.0, 0, 0, 0])
        np.testing.assert_allclose(plain.site(name).pos, [0.0, -sign * bicycle.CG_ARM, 0.0])
    heavy = bicycle.BicycleParams(rider_mass=70.0, gravity=9.0)
    assert bicycle.cg_force_per_metre(heavy) == pytest.approx(70.0 * 9.0 / (2 * bicycle.CG_ARM))


# --- State vector ---------------------------------------------------------------


def random_states(n, seed=0):
    rng = np.random.default_rng(seed)
    return np.column_stack(
        [
            rng.uniform(-0.5, 0.5, n),
            rng.uniform(-2, 2, n),
            rng.uniform(-0.3, 0.3, n),
            rng.uniform(-1, 1, n),
        ]
    )


def test_state_round_trip_and_getters():
    env = make_env()
    physics = env.physics
    states = random_states(50)
    qpos, qvel = physics.qpos_qvel_from(states)
    np.testing.assert_allclose(physics.states_from(qpos, qvel), states, atol=1e-12)
    physics.set_state_vector(states[3])
    np.testing.assert_allclose(physics.state_vector(), states[3], atol=1e-12)
    steer, steer_rate, roll, roll_rate = states[3]
    assert physics.steer_angle() == pytest.approx(steer)
    assert physics.steer_rate() == pytest.approx(steer_rate)
    assert physics.roll_angle() == pytest.approx(roll)
    assert physics.roll_rate() == pytest.approx(roll_rate)
    with pytest.raises(ValueError, match="shape"):
        physics.set_state_vector([0.0, 0.0, 0.0])


def test_roll_angle_is_the_lean_from_vertical():
    """A frame rotated 0.2 rad about +x (the bicycle leaning right) reads roll 0.2."""
    physics = make_env().physics
    qpos = np.zeros((1, physics.model.nq))
    qpos[0, 3:7] = [math.cos(0.1), math.sin(0.1), 0.0, 0.0]
    state = physics.states_from(qpos, np.zeros((1, physics.model.nv)))[0]
    assert state[2] == pytest.approx(0.2)
    # Leaning right lowers the frame's right side: its +y (left) axis points up.
    physics.set_state_vector([0.0, 0.0, 0.2, 0.0])
    assert physics.named.data.xmat["frame"].reshape(3, 3)[2, 1] == pytest.approx(math.sin(0.2))


def test_set_state_puts_both_tyres_on_the_floor_rolling_without_slip():
    physics = make_env(speed=4.0).physics
    model, data = physics.model.ptr, physics.data.ptr
    for state in random_states(10, seed=1):
        physics.set_state_vector(state)  # runs mj_forward
        assert data.ncon == 2
        for contact in data.contact[:2]:
            assert abs(contact.dist) < 1e-5  # knife edge vs the 5 mm ellipsoid: micrometres
            body = max(model.geom_bodyid[contact.geom[0]], model.geom_bodyid[contact.geom[1]])
            jac = np.zeros((3, model.nv))
            mujoco.mj_jac(model, data, jac, None, contact.pos, body)
            assert np.abs(jac @ data.qvel).max() < 5e-4  # material point at rest (m/s, vs 4 m/s)
        assert physics.forward_speed() == pytest.approx(4.0, rel=1e-9)


def test_frame_pitch_is_even_and_zero_upright():
    assert bicycle.frame_pitch(0.0, 0.0) == pytest.approx(0.0, abs=1e-15)
    roll, steer = np.array([0.1, 0.2, 0.0]), np.array([0.3, -0.2, 0.5])
    np.testing.assert_allclose(bicycle.frame_pitch(roll, steer), bicycle.frame_pitch(-roll, -steer), atol=1e-14)
    # Steering lowers the front (the tilted steer axis): positive pitch (nose down).
    assert bicycle.frame_pitch(0.0, 0.5) > 1e-3


# --- Task -----------------------------------------------------------------------


def test_controls_draw_rider_noise_and_add_speed():
    task = bicycle.Task(speed=3.0, cg_noise=0.02)
    rng = np.random.RandomState(0)
    ctrl = task.controls(np.array([[2.0], [-2.0], [0.0]] * 1000), rng)
    assert ctrl.shape == (3000, 4)
    np.testing.assert_array_equal(ctrl[:, 0], [2.0, -2.0, 0.0] * 1000)
    np.testing.assert_array_equal(ctrl[:, 1], ctrl[:, 2])  # both forces of the couple
    assert np.all(np.abs(ctrl[:, 1]) <= 0.02) and np.ptp(ctrl[:, 1]) > 0.039
    assert abs(ctrl[:, 1].mean()) < 1e-3  # uniform on [-2 cm, 2 cm]: mean 0, std 11.5 mm
    assert ctrl[:, 1].std() == pytest.approx(0.02 / math.sqrt(3), rel=0.05)
    np.testing.assert_array_equal(ctrl[:, 3], 3.0)
    again = task.controls(np.zeros((3000, 1)), np.random.RandomState(0))
    np.testing.assert_array_equal(again[:, 1], ctrl[:, 1])


def test_controls_each_is_controls_row_by_row():
    for noise in (0.02, 0.0):
        task = bicycle.Task(speed=3.0, cg_noise=noise)
        values = np.array([[2.0], [-2.0], [0.5], [0.0]])
        streams = [np.random.default_rng(k) for k in range(4)]
        rows = np.concatenate([task.controls(values[k : k + 1], streams[k]) for k in range(4)])
        again = [np.random.default_rng(k) for k in range(4)]
        np.testing.assert_array_equal(task.controls_each(values, again), rows)
        # Each stream is left where row-by-row drawing leaves it.
        assert [r.random() for r in again] == [r.random() for r in streams]
    with pytest.raises(ValueError, match="one random stream per row"):
        task.controls_each(values, again[:2])


def test_zero_noise_draws_nothing():
    task = bicycle.Task(cg_noise=0.0)
    rng = np.random.RandomState(4)
    before = rng.get_state()[1].copy()
    ctrl = task.controls(np.ones((50, 1)), rng)
    np.testing.assert_array_equal(rng.get_state()[1], before)
    assert rng.get_state()[2] == 624  # position in the Mersenne state: untouched
    np.testing.assert_array_equal(ctrl[:, 1:3], 0.0)
    # Through the environment: the episode's random stream is only read by resets.
    quiet, other = make_env(cg_noise=0.0, random=2), make_env(cg_noise=0.0, random=2)
    quiet.reset()
    other.reset()
    for _ in range(20):
        quiet.step([0.0])
    np.testing.assert_array_equal(quiet.reset().observation["state"], other.reset().observation["state"])


def test_cg_offset_is_redrawn_every_step_from_the_task_random():
    env = make_env(cg_noise=0.02, random=6)
    env.reset()
    expected = copy.deepcopy(env.task.random).uniform(-0.02, 0.02, size=100)
    offsets = []
    for _ in range(100):
        env.step([0.0])
        offsets.append(env.physics.cg_offset())
    np.testing.assert_array_equal(offsets, expected)
    assert np.abs(offsets).max() <= 0.02 and np.ptp(offsets) > 0.03


def settled_upright(physics, seconds=0.3):
    """Integration state of the bicycle rolling upright for ``seconds`` (tyre loads settled)."""
    model = physics.model.ptr
    data = mujoco.MjData(model)
    qpos, qvel = physics.qpos_qvel_from(np.zeros((1, bicycle.Physics.STATE_SIZE)))
    data.qpos[:], data.qvel[:] = qpos[0], qvel[0]
    data.ctrl[:] = bicycle.control_vector(0.0, 0.0, physics.target_speed())[0]
    for _ in range(int(round(seconds / model.opt.timestep))):
        mujoco.mj_step(model, data)
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    row = np.zeros(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, row, spec)
    return row


def one_step(physics, model, row, cg_offset):
    """Paper state after one 10 ms control step of ``model`` from ``row``, CG offset held."""
    data = mujoco.MjData(model)
    mujoco.mj_setState(model, data, row, mujoco.mjtState.mjSTATE_INTEGRATION)
    data.ctrl[:] = bicycle.control_vector(0.0, cg_offset, physics.target_speed())[0]
    for _ in range(int(round(bicycle.CONTROL_TIMESTEP / model.opt.timestep))):
        mujoco.mj_step(model, data)
    return physics.states_from(data.qpos[None], data.qvel[None])[0]


def test_cg_noise_is_the_rider_weight_moved_sideways():
    """The couple kicks roll and steer rates as the rider's centre of mass moved d does.

    Known answer: the benchmark's linearised equations, M q'' = f with the
    displaced weight's moment m g d on the roll coordinate, give over one step
    dt the rate kicks -M^-1[:, roll] m g d dt (d to the left leans left). The
    same kicks come from moving the rider body's centre of mass (body_ipos,
    constants recomputed by mj_setConst) with the couple off. Measured: roll
    rate -1.912e-3 rad/s for d = 2 cm (analytic -1.876e-3); the old servo's
    rider kicked it by 0.21 rad/s RMS.
    """
    physics = make_env(cg_noise=0.0).physics
    model = physics.model.ptr
    row = settled_upright(physics)
    base = one_step(physics, model, row, 0.0)
    moved = mujoco.MjModel.from_xml_string(*bicycle.model_xml())
    rider = moved.body("rider").id
    analytic_per_metre = -np.linalg.inv(BENCH_M)[:, 0] * 60.0 * 9.81 * bicycle.CONTROL_TIMESTEP
    for d in (0.02, -0.02, 0.005):
        kick = one_step(physics, model, row, d) - base
        moved.body_ipos[rider] = [0.0, d, 0.0]
        mujoco.mj_setConst(moved, mujoco.MjData(moved))
        displaced = one_step(physics, moved, row, 0.0) - base
        np.testing.assert_allclose(kick, displaced, rtol=0.01, atol=1e-7)
        # [steer rate, roll rate] against the benchmark's mass matrix.
        np.testing.assert_allclose(kick[[3, 1]], analytic_per_metre * d, rtol=0.05)
        assert kick[3] * d < 0.0 and 1e-4 < abs(kick[3]) < 3e-3


def test_reward_and_fall():
    task = bicycle.Task()
    limit = math.pi / 15
    states = np.array(
        [
            [0, 0, 0, 0],
            [0.3, 1, limit - 1e-6, -2],
            [0, 0, -limit - 1e-6, 0],
            [0, 0, limit + 1e-6, 0],
        ]
    )
    np.testing.assert_array_equal(task.batch_absorbing(states), [False, False, True, True])
    np.testing.assert_array_equal(task.batch_reward(states), [1.0, 1.0, 0.0, 0.0])


def test_episode_defaults():
    assert inspect.signature(bicycle.balance).parameters["time_limit"].default == 1000.0
    assert make_env().control_timestep() == pytest.approx(0.01)
    rolls = [make_env(random=seed).reset().observation["state"] for seed in range(20)]
    rolls = np.array(rolls)
    np.testing.assert_array_equal(rolls[:, [0, 1, 3]], 0.0)
    assert np.all(np.abs(rolls[:, 2]) <= math.radians(1.0)) and np.ptp(rolls[:, 2]) > 0.01


def test_speed_servo_holds_speed():
    env = make_env(speed=2.778, cg_noise=0.0)
    env.reset()
    for _ in range(100):
        env.step([0.0])
    assert env.physics.forward_speed() == pytest.approx(2.778, rel=2e-3)


def test_rollout_reproduces_the_environment():
    """The rider noise enters through ctrl only, so mujoco.rollout replays an episode exactly."""
    env = make_env(random=3)
    env.reset()
    physics = env.physics
    model, data = physics.model.ptr, physics.data.ptr
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    start = np.zeros(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, start, spec)
    random = copy.deepcopy(env.task.random)
    actions = bicycle.ACTIONS[np.random.default_rng(0).integers(0, 3, 30)]
    states = [env.step(a).observation["state"] for a in actions]
    ctrl = env.task.controls(actions, random)
    substeps = int(round(bicycle.CONTROL_TIMESTEP / model.opt.timestep))
    rolled, _ = mujoco.rollout.rollout(
        model, mujoco.MjData(model), start[None], np.repeat(ctrl, substeps, axis=0)[None]
    )
    nq = model.nq
    qpos = rolled[0, substeps - 1 :: substeps, 1 : 1 + nq]
    qvel = rolled[0, substeps - 1 :: substeps, 1 + nq : 1 + nq + model.nv]
    np.testing.assert_allclose(physics.states_from(qpos, qvel), np.array(states), atol=1e-9)


# --- Validation against the benchmark ---------------------------------------------


@pytest.mark.parametrize("speed", [2.778, 4.0, 5.0])
def test_lateral_eigenvalues_match_the_benchmark(speed):
    ours = bicycle_stability.lateral_eigenvalues(speed)
    bench = benchmark_eigenvalues(speed)
    for target in bench:
        if abs(target) < 0.5 and abs(target.imag) < 1e-9:
            continue  # capsize near zero: checked by the window test
        nearest = ours[np.argmin(np.abs(ours - target))]
        assert abs(nearest - target) < 0.08 * abs(target) + 0.1, (speed, target, ours)
    weave = ours[ours.imag > 1e-2]
    assert len(weave) == 1


def test_stability_window_matches_the_benchmark():
    weave, capsize = bicycle_stability.stability_window()
    assert weave == pytest.approx(BENCH_WEAVE_SPEED, rel=0.02)  # measured 4.341 (+1.1 %)
    assert capsize == pytest.approx(BENCH_CAPSIZE_SPEED, rel=0.01)  # measured 6.029 (+0.08 %)


def test_wider_tyres_lower_the_capsize_speed():
    """A rounder tyre crown (radius b^2 / r) destabilises the capsize mode."""
    knife = bicycle_stability.capsize_growth(5.9)
    wide = bicycle_stability.capsize_growth(5.9, bicycle.BicycleParams(tyre_half_width=0.03))
    assert knife < 0.0 < wide


def test_uncontrolled_falls_below_the_window_and_recovers_inside():
    rolls, timestep = run(make_env(speed=2.778, cg_noise=0.0, random=1), lambda s: 0.0, 10.0)
    assert timestep.last() and timestep.discount == 0.0 and len(rolls) < 500
    for speed in (4.8, 5.6):
        env = make_env(speed=speed, cg_noise=0.0, time_limit=10.0)
        env.reset()
        env.physics.set_state_vector([0.0, 0.0, 0.05, 0.0])  # 2.9 degrees to the right
        rolls = [env.step([0.0]).observation["state"][2] for _ in range(1000)]
        # The weave dies out; the slow capsize mode then brings the roll back down.
        assert max(np.abs(rolls)) < 0.1 and abs(rolls[-1]) < 0.6 * 0.05, (speed, rolls[-1])


def test_counter_steering():
    """Steer torque to the right first leans the bicycle to the left (non-minimum phase)."""
    env = make_env(cg_noise=0.0)
    env.reset()
    env.physics.set_state_vector([0.0, 0.0, 0.0, 0.0])
    rolls, steers = [], []
    for i in range(40):
        state = env.step([2.0 if i < 10 else 0.0]).observation["state"]
        steers.append(state[0])
        rolls.append(state[2])
    rolls = np.array(rolls)
    assert steers[9] > 0.02  # handlebar turned right
    first = np.flatnonzero(np.abs(rolls) > 1e-3)[0]
    assert rolls[first] < 0.0 and rolls.min() < -5e-3  # leans left first


@pytest.mark.slow
@pytest.mark.parametrize("discrete", [False, True])
def test_steer_into_the_fall_balances_for_a_minute(discrete):
    env = make_env(speed=2.778, cg_noise=0.02, random=5, time_limit=60.0)
    rolls, timestep = run(env, lambda s: steer_into_fall(s, discrete), 60.0)
    assert len(rolls) == 6001 and timestep.discount == 1.0
    assert np.abs(rolls).max() < math.radians(6.0)
    # Without the controller the same noisy bicycle falls within seconds.
    rolls, timestep = run(make_env(speed=2.778, cg_noise=0.02, random=5), lambda s: 0.0, 60.0)
    assert timestep.discount == 0.0 and len(rolls) < 1000


def test_start_roll_sets_the_range_of_start_rolls_and_is_checked():
    bike = bicycle

    rolls = {}
    for start_roll in (bike.START_ROLL, 0.15):
        env = suite.load("bicycle", "balance", task_kwargs={"random": 0, "start_roll": start_roll})
        rolls[start_roll] = np.array([env.reset().observation["state"][2] for _ in range(200)])
    assert np.abs(rolls[bike.START_ROLL]).max() <= bike.START_ROLL
    assert 0.12 < np.abs(rolls[0.15]).max() <= 0.15  # the wider range is used, and held to
    default = suite.load("bicycle", "balance", task_kwargs={"random": 0}).reset().observation["state"]
    assert default[2] == rolls[bike.START_ROLL][0]  # the default is unchanged
    with pytest.raises(ValueError, match=r"start_roll must be in \[0, 0.2094\) rad"):
        suite.load("bicycle", "balance", task_kwargs={"start_roll": 0.3})
