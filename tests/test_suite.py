"""Conformance of every task in ``suite.ALL_TASKS``: dm_env and gymnasium contracts,
seeding, rendering, argument checking and divergence handling.

Episodes are kept short (``time_limit`` in task_kwargs) so the file stays fast.
"""

import copy
import inspect

import dm_env
import mujoco
import mujoco.rollout
import numpy as np
import pytest
from absl.testing import absltest
from dm_control.rl import control
from dm_env import test_utils

from tatl_mj import suite

SHORT_TIME_LIMIT_S = 0.3  # physics tasks, seconds
SHORT_TIME_LIMIT_STEPS = 12  # gridworld, steps
N_ACTIONS_IN_SEQUENCE = 40  # crosses at least one episode end with the limits above


def _accepts(domain, task, name):
    return name in inspect.signature(suite.DOMAINS[domain].TASKS[task]).parameters


def _load(domain, task, seed=0, **extra):
    kwargs = {"random": seed, **extra}
    if _accepts(domain, task, "time_limit"):
        kwargs["time_limit"] = SHORT_TIME_LIMIT_STEPS if domain == "gridworld" else SHORT_TIME_LIMIT_S
    return suite.load(domain, task, task_kwargs=kwargs)


def _is_physics(env):
    return isinstance(env, control.Environment)


def _action_cycle(domain, n):
    actions = suite.action_set(domain)
    return [actions[i % len(actions)] for i in range(n)]


TASK_IDS = [f"{d}-{t}" for d, t in suite.ALL_TASKS]
PHYSICS_TASKS = [(d, t) for d, t in suite.ALL_TASKS if d != "gridworld"]
PHYSICS_IDS = [f"{d}-{t}" for d, t in PHYSICS_TASKS]


def test_suite_lists_every_domain_and_task():
    assert set(suite.DOMAINS) == {"cartpole", "pendulum", "mountain_car", "bicycle", "gridworld"}
    assert all(suite.DOMAINS[d].TASKS for d in suite.DOMAINS), "a domain has no tasks"
    assert len(suite.ALL_TASKS) == len(set(suite.ALL_TASKS))


# --- dm_env conformance: one generated TestCase per task -----------------------


def _dm_env_case(domain, task):
    class Case(test_utils.EnvironmentTestMixin, absltest.TestCase):
        def make_object_under_test(self):
            return _load(domain, task)

        def make_action_sequence(self):
            yield from _action_cycle(domain, N_ACTIONS_IN_SEQUENCE)

        def test_reaches_an_episode_end(self):
            self.environment.reset()
            steps = [self.environment.step(a) for a in _action_cycle(domain, N_ACTIONS_IN_SEQUENCE)]
            self.assertTrue(any(s.last() for s in steps))

    name = f"TestDmEnv_{domain}_{task}"
    Case.__name__ = Case.__qualname__ = name
    return name, Case


for _domain, _task in suite.ALL_TASKS:
    _name, _case = _dm_env_case(_domain, _task)
    globals()[_name] = _case
del _domain, _task, _name, _case


# --- gymnasium through shimmy -----------------------------------------------------


@pytest.mark.filterwarnings("ignore:.*(Box observation space|symmetric and normalized).*:UserWarning")
# shimmy's DmControlCompatibilityV0 needs dm_control's physics and task; the grid
# world is a plain dm_env.Environment (its dm_env contract is checked above).
@pytest.mark.parametrize("domain, task", PHYSICS_TASKS, ids=PHYSICS_IDS)
def test_gymnasium_check_env(domain, task):
    from gymnasium.utils.env_checker import check_env
    from shimmy import DmControlCompatibilityV0

    env = DmControlCompatibilityV0(_load(domain, task))
    check_env(env, skip_render_check=True)
    env.close()


# --- seeding --------------------------------------------------------------------


def _trace(domain, task, seed, n=25):
    extra = {"random_start": True} if _accepts(domain, task, "random_start") else {}
    env = _load(domain, task, seed=seed, **extra)
    timestep = env.reset()
    states, rewards = [timestep.observation["state"].copy()], []
    for action in _action_cycle(domain, n):
        timestep = env.step(action)
        states.append(timestep.observation["state"].copy())
        rewards.append(timestep.reward)
    return np.array(states), np.array(rewards, dtype=float)


@pytest.mark.parametrize("domain, task", suite.ALL_TASKS, ids=TASK_IDS)
def test_same_seed_same_run_and_seeds_differ_at_start(domain, task):
    states_a, rewards_a = _trace(domain, task, seed=11)
    states_b, rewards_b = _trace(domain, task, seed=11)
    np.testing.assert_array_equal(states_a, states_b)
    np.testing.assert_array_equal(rewards_a, rewards_b)
    assert np.all(np.isfinite(states_a))
    starts = {tuple(_trace(domain, task, seed=s, n=0)[0][0]) for s in range(4)}
    assert len(starts) > 1, "different seeds gave the same start state"


# --- rendering ------------------------------------------------------------------


@pytest.mark.parametrize("domain, task", PHYSICS_TASKS, ids=PHYSICS_IDS)
def test_start_configurations_are_successive_resets(domain, task):
    # The sampler starts many episodes with one draw; it must be the draws of
    # as many resets, bit for bit, and leave the same random state behind.
    looped, batched = _load(domain, task, seed=4), _load(domain, task, seed=4)
    resets = []
    for _ in range(6):
        looped.reset()
        resets.append((looped.physics.data.qpos.copy(), looped.physics.data.qvel.copy()))
    qpos, qvel = batched.task.start_configurations(batched.physics, 6)
    np.testing.assert_array_equal(qpos, np.stack([r[0] for r in resets]))
    np.testing.assert_array_equal(qvel, np.stack([r[1] for r in resets]))
    assert len({tuple(q) for q in qpos}) == 6  # six different starts
    assert looped.task.random.uniform() == batched.task.random.uniform()


@pytest.mark.parametrize("domain, task", PHYSICS_TASKS, ids=PHYSICS_IDS)
def test_renders_a_frame_from_the_tracking_camera(domain, task):
    env = _load(domain, task)
    env.reset()
    env.step(suite.action_set(domain)[-1])
    frame = env.physics.render(height=480, width=640, camera_id="tracking")
    assert frame.shape == (480, 640, 3) and frame.dtype == np.uint8
    colours = np.unique(frame.reshape(-1, 3), axis=0)
    assert frame.std() > 10 and len(colours) > 50, "blank or nearly uniform frame"


# --- argument checking ------------------------------------------------------------


def test_load_rejects_unknown_names_listing_the_valid_ones():
    with pytest.raises(ValueError, match="valid domains.*cartpole"):
        suite.load("acrobot", "swingup")
    with pytest.raises(ValueError, match="valid tasks.*climb"):
        suite.load("mountain_car", "descend")
    with pytest.raises(ValueError, match="unknown task_kwargs.*'colour'.*valid.*random"):
        suite.load("gridworld", "windy", task_kwargs={"colour": "red"})
    with pytest.raises(ValueError, match="unknown task_kwargs.*'colour'.*valid.*time_limit"):
        suite.load("mountain_car", "climb", task_kwargs={"colour": "red"})
    for bad in ("abc", -1, 1.5):
        with pytest.raises(ValueError, match=r"task_kwargs\['random'\] must be None, an integer seed"):
            suite.load("cartpole", "balance", task_kwargs={"random": bad})
    for good in (None, 3, [3, 1], np.random.RandomState(3)):  # what dm_control accepts
        suite.load("gridworld", "plain", task_kwargs={"random": good}).reset()


@pytest.mark.parametrize("domain", sorted(suite.DOMAINS))
def test_discrete_action_maps_indices_and_rejects_bad_ones(domain):
    actions = suite.action_set(domain)
    assert len(actions) >= 2
    for i, expected in enumerate(actions):
        np.testing.assert_array_equal(suite.discrete_action(domain, i), expected)
    for bad in (-1, len(actions)):
        with pytest.raises(ValueError, match="out of range"):
            suite.discrete_action(domain, bad)
    task = next(iter(suite.DOMAINS[domain].TASKS))
    env = _load(domain, task)
    env.reset()
    for action in actions:  # every discrete action is a valid env action
        env.action_spec().validate(np.asarray(action, dtype=env.action_spec().dtype))
        env.step(action)


def test_discrete_action_values():
    np.testing.assert_array_equal(suite.discrete_action("mountain_car", 0), [-1.0])
    np.testing.assert_array_equal(suite.discrete_action("mountain_car", 2), [1.0])
    assert suite.discrete_action("gridworld", 3) == 3


# --- divergence -------------------------------------------------------------------


@pytest.mark.parametrize("domain, task", PHYSICS_TASKS, ids=PHYSICS_IDS)
def test_divergence_ends_the_episode_cleanly(domain, task):
    env = _load(domain, task)
    first = env.reset()
    # Far above MuJoCo's mjMAXVAL (1e10): the step raises mjWARN_BADQVEL.
    env.physics.data.qvel[:] = 1e12
    timestep = env.step(suite.action_set(domain)[0])
    assert timestep.last() and timestep.discount == 0.0 and timestep.reward == 0.0
    assert np.all(np.isfinite(timestep.observation["state"]))
    np.testing.assert_array_equal(timestep.observation["state"], first.observation["state"])
    assert isinstance(env.diverged, str) and "mjWARN_BADQVEL" in env.diverged
    after = env.step(suite.action_set(domain)[0])
    assert after.step_type is dm_env.StepType.FIRST and env.diverged is None
    assert np.all(np.isfinite(after.observation["state"]))


@pytest.mark.parametrize("domain, task", suite.ALL_TASKS)
def test_describe_agrees_with_the_environment(domain, task):
    """suite.describe states what a built environment does, without building one."""
    description = suite.describe(domain, task)
    env = suite.load(domain, task, task_kwargs={"random": 0})
    state = env.reset().observation["state"]
    assert description.state_dim == len(state) and len(description.periodic) == len(state)
    spec = env.action_spec()
    assert description.discrete == isinstance(spec, dm_env.specs.DiscreteArray)
    assert description.n_actions == len(suite.action_set(domain))
    if not description.discrete:
        np.testing.assert_array_equal(description.action_values, suite.action_set(domain))
        np.testing.assert_array_equal(description.action_low, np.broadcast_to(spec.minimum, spec.shape))
        np.testing.assert_array_equal(description.action_high, np.broadcast_to(spec.maximum, spec.shape))
        assert description.control_timestep == pytest.approx(env.control_timestep())
    for i, periodic in enumerate(description.periodic):
        if periodic:  # observed angles are wrapped
            assert -np.pi <= state[i] < np.pi
    assert np.all(description.state_low <= state) and np.all(state <= description.state_high)


def test_describe_gives_the_known_model_only_where_it_is_exact():
    model = suite.describe("gridworld", "windy").known_model
    env = suite.load("gridworld", "windy", task_kwargs={"random": 0})
    next_state, reward, absorbing, cells = model()
    for i in (0, 17, 40):
        for a in range(4):
            env.reset()
            if tuple(cells[i]) == (5, 8):  # the goal ends an episode; it cannot be a start
                continue
            env.set_state_vector(cells[i])
            timestep = env.step(a)
            np.testing.assert_array_equal(timestep.observation["state"], cells[next_state[i, a]])
            assert timestep.reward == reward[i, a]
    assert suite.describe("gridworld", "windy", {"stochastic_wind": True}).known_model is None
    assert suite.describe("pendulum", "swingup").angle_origin == (np.pi, 0.0)
    with pytest.raises(ValueError, match="unknown task_kwargs \\['wind'\\]"):
        suite.describe("gridworld", "windy", {"wind": 2})


# --- cost of a step -----------------------------------------------------------------


def test_a_step_computes_the_state_once_and_forgets_it():
    env = suite.load("cartpole", "balance", task_kwargs={"random": 0})
    env.reset()
    physics = env.physics
    calls = []
    state_vector = type(physics).state_vector

    def counting(self):
        calls.append(1)
        return state_vector(self)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(type(physics), "state_vector", counting)
        timestep = env.step(np.zeros(1))
        assert len(calls) == 1  # reward, observation and termination share it
        np.testing.assert_array_equal(timestep.observation["state"], state_vector(physics))
    # Once the step has returned, the task reads the physics afresh.
    physics.set_state_vector(np.array([0.0, 0.0, 0.5, 0.0]))  # past 12 degrees
    assert env.task.get_termination(physics) == 0.0 and env.task.get_reward(physics) == 0.0
    np.testing.assert_array_equal(env.task.get_observation(physics)["state"], [0.0, 0.0, 0.5, 0.0])


def test_models_are_compiled_once_and_never_shared():
    a = suite.load("pendulum", "swingup", task_kwargs={"random": 0})
    b = suite.load("pendulum", "swingup", task_kwargs={"random": 0})
    assert a.physics.model.ptr is not b.physics.model.ptr
    a.physics.model.body_mass[1] *= 2.0  # a runtime model edit stays with its own physics
    assert b.physics.model.body_mass[1] * 2.0 == a.physics.model.body_mass[1]
    c = suite.load("pendulum", "swingup", task_kwargs={"random": 0})
    assert c.physics.model.body_mass[1] == b.physics.model.body_mass[1]


@pytest.mark.parametrize("domain,task", [("cartpole", "balance"), ("pendulum", "swingup")])
def test_skipping_collision_and_constraints_changes_no_number(domain, task):
    # These models disable MuJoCo's contact and constraint stages for speed. Nothing in
    # them can touch or be constrained, so the dynamics must be the same bit for bit.
    model = suite.load(domain, task, task_kwargs={"random": 0}).physics.model.ptr
    skipped = mujoco.mjtDisableBit.mjDSBL_CONTACT | mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
    assert model.opt.disableflags & skipped == skipped
    assert not model.jnt_limited.any() and not model.dof_frictionloss.any()
    assert model.neq == 0 and model.ntendon == 0 and not (model.geom_contype | model.geom_conaffinity).any()
    full = copy.copy(model)
    full.opt.disableflags &= ~skipped
    # Starts far from rest (fast spins, the cart far out) and bang-bang forces for 20 s.
    rng = np.random.default_rng(0)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    data = mujoco.MjData(model)
    starts = np.empty((16, mujoco.mj_stateSize(model, spec)))
    for row in starts:
        mujoco.mj_resetData(model, data)
        data.qpos[:] = rng.uniform(-3, 3, model.nq)
        data.qvel[:] = rng.uniform(-10, 10, model.nv)
        mujoco.mj_getState(model, data, row, spec)
    limit = model.actuator_ctrlrange[:, 1]
    controls = rng.choice([-1.0, 1.0], size=(16, 2000, model.nu)) * limit
    skipping, _ = mujoco.rollout.rollout(model, data, starts, controls)
    computing, _ = mujoco.rollout.rollout(full, mujoco.MjData(full), starts, controls)
    np.testing.assert_array_equal(skipping, computing)
    assert np.abs(skipping[:, -1, 1 : 1 + model.nq]).max() > 10  # it went somewhere


# --- Contexts -----------------------------------------------------------------------------

PHYSICS_TASKS = [(d, t) for d, t in suite.ALL_TASKS if not suite.describe(d, t).discrete]


def test_docs_list_every_context_key_with_its_unit_and_range():
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "suite.md").read_text()
    rows = set()
    for line in text.split("## Contexts", 1)[1].splitlines():
        cells = [c.strip().strip("`") for c in line.strip().strip("|").split("|")]
        if len(cells) == 6 and cells[1] not in ("key", "---"):
            task, key, unit, valid, kind = cells[0].split(" ")[0].strip("`"), *cells[1:5]
            tasks = [f"pendulum/{t}" for t in suite.DOMAINS["pendulum"].TASKS] if task == "pendulum/*" else [task]
            rows |= {(t, key, unit, valid.split(",")[0], kind) for t in tasks}
    declared = {
        (f"{d}/{t}", k.name, k.unit, f"{k.low:g} .. {k.high:g}", k.side)
        for d, t in PHYSICS_TASKS
        for k in suite.context_spec(d, t).keys
    }
    assert rows == declared
    # Every condition the sweeps vary is a context key of its target task.
    sweeps = {("pendulum/swingup_flipped", "gain"), ("pendulum/swingup_timevarying", "amplitude")}
    sweeps |= {("bicycle/balance", "cg_noise"), ("bicycle/balance", "speed")}
    assert sweeps <= {(task, key) for task, key, *_ in declared}


@pytest.mark.parametrize("domain, task", PHYSICS_TASKS)
def test_a_context_builds_the_task_a_task_kwargs_would(domain, task):
    # Each key at the middle of its range: the values check, and the task built with them has them.
    spec = suite.context_spec(domain, task)
    context = {k.name: (k.low + k.high) / 2 for k in spec.keys}
    if task == "swingup_timevarying":
        context["amplitude"] = 1.0
    values = suite.check_context(domain, task, context)
    assert list(values) == list(spec.names) and values == context
    assert suite.check_context(domain, task, {}) == suite.contexts.defaults(spec, suite.DOMAINS[domain].TASKS[task], {})
    env = suite.load(domain, task, task_kwargs=suite.task_kwargs_with_context(domain, task, {"random": 0}, values))
    for key in spec.keys:
        if key.side == "task":
            assert getattr(env.task, key.name) == values[key.name]
        else:
            owner = env.task.params if domain == "pendulum" else None
            if owner is not None and key.in_params:
                assert getattr(owner, key.name) == values[key.name]
    env.reset()
    env.step(suite.action_set(domain)[0])


def test_a_bad_context_names_the_key_and_the_valid_ones():
    with pytest.raises(
        ValueError, match=r"^cartpole/balance context: unknown context key\(s\) \['mass'\]; valid: cart_mass"
    ):
        suite.check_context("cartpole", "balance", {"mass": 1.0})
    with pytest.raises(ValueError, match=r"context speed must be a number in \[0.1, 20\] m/s, got nan"):
        suite.check_context("bicycle", "balance", {"speed": float("nan")})
    with pytest.raises(ValueError, match="takes no context"):
        suite.check_context("gridworld", "plain", {"wind": 1.0})
