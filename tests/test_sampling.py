"""The batched sampler reproduces the dm_control environments exactly (issue 5)."""

from __future__ import annotations

import importlib.util
import sys
import tracemalloc

import numpy as np
import pytest

from tatl_mj import sampling, suite
from tatl_mj.policy import StatePolicy
from tatl_mj.sampling import collection, schedule, simulator
from tatl_mj.sampling.checks import DrawingPolicy

# Rider noise: collect() draws it from each episode's own blocks, the environment
# from its task's random; with zero noise nothing is drawn and both agree.
QUIET = {("bicycle", "balance"): {"cg_noise": 0.0}}
# The issue asks for bitwise or 1e-12: everything is bitwise, the bicycle's
# computed paper state (trig, a Newton solve, a 3x3 solve) included.
ATOL = 0.0


def assert_close(actual, desired, err_msg=""):
    np.testing.assert_allclose(actual, desired, rtol=0, atol=ATOL, err_msg=err_msg)


FIELDS = ("states", "actions", "rewards", "next_states", "absorbing", "last")


def assert_same_transitions(a, b):
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


PHYSICS_TASKS = [t for t in suite.ALL_TASKS if t[0] != "gridworld"]
BATCHED_TASKS = [t for t in PHYSICS_TASKS if sampling.is_batched(*t)]


def replay(domain: str, task: str, tr, seed: int, task_kwargs=None) -> None:
    """Steps one environment (random=seed) through ``tr``'s episodes and actions."""
    env = suite.load(domain, task, task_kwargs={**(task_kwargs or {}), "random": seed})
    actions = suite.action_set(domain)
    i = 0
    while i < len(tr):
        state = env.reset().observation["state"]
        while i < len(tr):
            assert_close(tr.states[i], state, err_msg=f"state {i}")
            timestep = env.step(actions[tr.actions[i]])
            state = timestep.observation["state"]
            assert_close(tr.next_states[i], state, err_msg=f"next state {i}")
            assert tr.rewards[i] == timestep.reward, i
            assert tr.absorbing[i] == (timestep.last() and timestep.discount == 0.0), i
            if i < len(tr) - 1:
                assert tr.last[i] == timestep.last(), i
            i += 1
            if timestep.last():
                break


def draws_noise(domain: str, task: str, task_kwargs=None) -> bool:
    env = suite.load(domain, task, task_kwargs={**(task_kwargs or {}), "random": 0})
    random = np.random.RandomState(0)
    before = random.get_state()[2]
    env.task.controls(np.asarray(suite.action_set(domain), np.float64)[:1], random)
    return random.get_state()[2] != before


@pytest.mark.parametrize("domain,task", suite.ALL_TASKS)
def test_collect_is_the_environment_loop(domain, task):
    # One episode at a time: bit-identical to the plain loop. Rider noise is each
    # episode's own in collect() (below), so it is silenced here.
    kwargs = QUIET.get((domain, task))
    tr = sampling.collect(domain, task, 300, seed=5, n_parallel=1, task_kwargs=kwargs)
    assert len(tr) == 300 and tr.last[-1]
    replay(domain, task, tr, seed=5, task_kwargs=kwargs)


@pytest.mark.parametrize("domain,task", BATCHED_TASKS)
def test_lockstep_collect_is_the_environment_loop(domain, task):
    kwargs = QUIET.get((domain, task))
    tr = sampling.collect(domain, task, 500, seed=11, n_parallel=13, n_threads=2, task_kwargs=kwargs)
    assert tr.last.sum() >= 2
    replay(domain, task, tr, seed=11, task_kwargs=kwargs)


def test_rider_noise_is_each_episodes_own():
    # The environment replays a noisy collection when each episode's controls are
    # the ones _EpisodeDraws documents: its block of the collection's streams, in start order.
    seed, n = 4, 700
    tr = sampling.collect("bicycle", "balance", n, seed=seed)
    assert tr.last.sum() >= 3
    sim = simulator.simulator_for("bicycle", "balance", None, 2)
    env = suite.load("bicycle", "balance", task_kwargs={"random": seed})
    # The draws' own task: the environment's controls are replaced below.
    task = suite.load("bicycle", "balance", task_kwargs={"random": seed}).task
    draws = collection.EpisodeDraws(sim, task, seed, 1, sim.step_limit(None))
    slot, episode, steps = np.zeros(1, np.int64), 0, 0
    rows = []

    def episode_controls(values, random):
        actions, controls = draws.take(slot, np.array([steps]), 1)
        rows.append(actions[0, 0])
        return controls[0]

    env.task.controls = episode_controls
    i = 0
    while i < n:
        draws.start(slot, np.array([episode]))
        state = env.reset().observation["state"]
        steps = 0
        while i < n:
            assert_close(tr.states[i], state, err_msg=f"state {i}")
            timestep = env.step(suite.action_set("bicycle")[tr.actions[i]])
            steps += 1
            state = timestep.observation["state"]
            assert_close(tr.next_states[i], state, err_msg=f"next state {i}")
            i += 1
            if timestep.last():
                break
        episode += 1
    np.testing.assert_array_equal(rows, tr.actions)  # the actions are the episodes' draws too


def test_an_episodes_draws_are_its_blocks():
    # Known answer: episode e's first block is row e of default_rng(seed)'s draws,
    # its block j after that default_rng([seed, e, j])'s. Mountain car's random
    # episodes run to the time limit (~400 steps), past the first block.
    seed, block = 3, collection.BLOCK
    tr = sampling.collect("mountain_car", "climb", 1200, seed=seed, n_parallel=2)
    episodes = np.split(tr.actions, np.flatnonzero(tr.last)[:-1] + 1)
    assert len(episodes) == 3 and block < len(episodes[0]) <= 2 * block
    n_actions = len(suite.action_set("mountain_car"))
    first = np.random.default_rng(seed).integers(n_actions, size=(3, block))
    for e, actions in enumerate(episodes):
        np.testing.assert_array_equal(actions[:block], first[e][: len(actions)])
        later = np.random.default_rng([seed, e, 1]).integers(n_actions, size=block)
        np.testing.assert_array_equal(actions[block:], later[: len(actions) - block])


@pytest.mark.parametrize("domain,task", [("bicycle", "balance"), ("cartpole", "balance"), ("pendulum", "swingup")])
def test_a_smaller_random_collection_is_the_head_of_a_larger_one(domain, task):
    # Episodes depend on the seed and their number alone, so budgets nest.
    big = sampling.collect(domain, task, 2500, seed=6)
    small = sampling.collect(domain, task, 900, seed=6)
    for name in FIELDS:
        expected = getattr(big, name)[:900].copy()
        if name == "last":
            expected[-1] = True  # the collected segment ends there
        np.testing.assert_array_equal(getattr(small, name), expected, err_msg=name)


@pytest.mark.parametrize(
    "domain,task,n,kwargs",
    [
        ("bicycle", "balance", 3000, {}),  # rider noise
        ("mountain_car", "climb", 3000, {}),
        ("mountain_car", "climb", 1500, {"max_episode_steps": 37}),
        ("cartpole", "balance", 2000, {}),
        ("pendulum", "swingup", 1000, {}),
    ],
)
def test_random_collections_depend_on_the_seed_alone(domain, task, n, kwargs, monkeypatch):
    # Not on how many episodes run together nor how many steps a call takes: the
    # multi-step calls, the one-step passes and one episode at a time agree.
    calls = []
    real = simulator.Simulator.advance_steps

    def counting(self, batch, ids, controls):
        calls.append(controls.shape[:2])
        return real(self, batch, ids, controls)

    monkeypatch.setattr(simulator.Simulator, "advance_steps", counting)
    many = sampling.collect(domain, task, n, seed=7, **kwargs)
    assert calls and max(k for k, _ in calls) > 1  # the multi-step path ran
    for parallel in (1, 5):
        assert_same_transitions(many, sampling.collect(domain, task, n, seed=7, n_parallel=parallel, **kwargs))
    monkeypatch.setattr(schedule, "MOST_STEPS", 1)  # one control step per pass
    calls.clear()
    one = sampling.collect(domain, task, n, seed=7, **kwargs)
    assert not calls
    assert_same_transitions(many, one)


def test_default_parallelism_leaves_the_data_alone(monkeypatch):
    sizes = []
    real = simulator.Simulator.new_batch
    monkeypatch.setattr(simulator.Simulator, "new_batch", lambda self, nsim: sizes.append(nsim) or real(self, nsim))
    default = sampling.collect("cartpole", "balance", 24_000, seed=3)
    assert_same_transitions(default, sampling.collect("cartpole", "balance", 24_000, seed=3, n_parallel=256))
    assert sizes == [schedule.default_parallel(24_000, random_actions=True), 256]  # collect() took the default


def test_random_collections_do_not_depend_on_the_schedule(monkeypatch):
    # How many episodes start and how many steps each call takes are speed choices:
    # any lengths within the call's bounds, and starting every free slot at once,
    # give the same transitions.
    want = sampling.collect("mountain_car", "climb", 2500, seed=8, max_episode_steps=120)
    rng = np.random.default_rng(0)
    monkeypatch.setattr(schedule, "call_length", lambda ended, ages, caps, cost, most: int(rng.integers(1, most + 1)))
    monkeypatch.setattr(schedule, "episodes_to_start", lambda n_free, total, n, *_: n_free if total < n else 0)
    assert_same_transitions(want, sampling.collect("mountain_car", "climb", 2500, seed=8, max_episode_steps=120))


def test_random_collections_start_from_the_lengths_of_earlier_ones(monkeypatch):
    # A speed choice only: a warm start changes how the episodes are stepped, not the data.
    sim = simulator.simulator_for("bicycle", "balance", None, 2)
    limit = sim.step_limit(None)
    sim.random_lengths.clear()
    first_calls = []
    real = simulator.Simulator.advance_steps

    def recording(self, batch, ids, controls):
        first_calls.append(len(controls))
        return real(self, batch, ids, controls)

    monkeypatch.setattr(simulator.Simulator, "advance_steps", recording)
    cold = sampling.collect("bicycle", "balance", 3000, seed=4)
    seen = sim.random_lengths[limit].copy()
    # Every episode that fell within the collection is in the histogram (some beyond it too).
    last = np.flatnonzero(cold.last)
    fell = np.bincount(np.diff(np.r_[-1, last])[cold.absorbing[last]])
    assert np.all(seen[: len(fell)] >= fell) and seen.sum() >= fell.sum() > 10
    cold_first, first_calls[:] = first_calls[0], []
    warm = sampling.collect("bicycle", "balance", 3000, seed=4)
    assert_same_transitions(cold, warm)
    assert cold_first == 2 and first_calls[0] > 2  # cold: the first call stays short; warm: it knows better
    assert sim.random_lengths[limit].sum() > seen.sum()
    upright = lambda s: np.where(s[:, 2] > 0, 2, 0)  # noqa: E731
    total = sim.random_lengths[limit].sum()
    sampling.collect("bicycle", "balance", 500, seed=4, policy=upright)  # a policy's lengths are its own
    assert sim.random_lengths[limit].sum() == total


def test_quiet_tasks_draw_no_noise():
    # Guards the test above: QUIET names every task whose controls draw noise,
    # and with its kwargs the task draws none.
    noisy = {t for t in BATCHED_TASKS if draws_noise(*t)}
    assert noisy == set(QUIET)
    assert not any(draws_noise(*t, task_kwargs=QUIET[t]) for t in QUIET)

    # ... and each task says so: the sampler maps a quiet task's controls lazily, from
    # the actions alone (with random=None).
    def says(domain, task, task_kwargs=None):
        return suite.load(domain, task, task_kwargs={**(task_kwargs or {}), "random": 0}).task.control_noise

    assert {t for t in BATCHED_TASKS if says(*t)} == noisy
    assert not any(says(*t, task_kwargs=QUIET[t]) for t in QUIET)

    # A user's task that overrides controls is taken to draw noise unless it says not.
    from tatl_mj.suite import cartpole

    class Offset(cartpole.Task):
        def controls(self, action_values, random):
            return super().controls(action_values, random) + random.uniform(-1, 1, size=(len(action_values), 1))

    assert Offset().control_noise and not cartpole.Task().control_noise


def test_contact_model_keeps_its_warm_start():
    # The bicycle's tyre contacts use the constraint solver's warm start; a long
    # lockstep episode stays bit-identical only if it is carried between steps.
    kwargs = QUIET[("bicycle", "balance")]
    upright = lambda s: np.where(s[:, 2] > 0, 2, 0)  # steer into the lean  # noqa: E731
    tr = sampling.collect("bicycle", "balance", 150, seed=2, policy=upright, task_kwargs=kwargs, n_parallel=3)
    env = suite.load("bicycle", "balance", task_kwargs={**kwargs, "random": 2})
    state = env.reset().observation["state"]
    for i in range(np.argmax(tr.last) + 1):
        assert_close(state, tr.states[i])
        state = env.step(suite.action_set("bicycle")[tr.actions[i]]).observation["state"]
    assert np.argmax(tr.last) > 50  # the episode was long enough to mean something


def test_episodes_are_contiguous_and_limited():
    tr = sampling.collect("cartpole", "balance", 2000, seed=0, max_episode_steps=7)
    follows = ~tr.last[:-1]
    np.testing.assert_array_equal(tr.next_states[:-1][follows], tr.states[1:][follows])
    assert not np.any(tr.absorbing & ~tr.last)
    ends = np.flatnonzero(tr.last)
    lengths = np.diff(np.concatenate([[-1], ends]))
    assert lengths.max() <= 7
    # dm_control: the time limit wins (discount 1) even if step 7 fails.
    assert not np.any(tr.absorbing[ends[lengths == 7]])
    assert tr.absorbing.any() and (~tr.absorbing[ends]).any()


@pytest.mark.parametrize("domain,task", [("bicycle", "balance"), ("cartpole", "balance")])
def test_one_step_episodes_fill_the_collection(domain, task):
    # Every episode ends in its first step: the collection still holds n, each
    # from the next reset.
    tr = sampling.collect(domain, task, 600, seed=2, max_episode_steps=1)
    assert len(tr) == 600 and tr.last.all()
    env = suite.load(domain, task, task_kwargs={"random": 2})
    starts = np.array([env.reset().observation["state"] for _ in range(600)])
    np.testing.assert_array_equal(tr.states, starts)


def test_deterministic_and_independent_of_threads():
    a = sampling.collect("cartpole", "balance", 3000, seed=3, n_threads=1)
    b = sampling.collect("cartpole", "balance", 3000, seed=3, n_threads=2)
    c = sampling.collect("cartpole", "balance", 3000, seed=4, n_threads=2)
    for name in ("states", "actions", "rewards", "next_states", "absorbing", "last"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert not np.array_equal(a.states, c.states)


def test_mujoco_threads_sets_the_default_thread_count_and_not_the_numbers():
    def policy(states):  # a deterministic bang-bang controller on the pole's lean
        return np.where(states[:, 2:3] > 0, 1.0, -1.0)

    assert simulator.simulator_for("cartpole", "balance", None, None).n_threads == 2
    two = sampling.evaluate("cartpole", "balance", policy, 20, seed=5, max_episode_steps=200)
    with sampling.mujoco_threads(1):
        assert simulator.simulator_for("cartpole", "balance", None, None).n_threads == 1
        assert simulator.simulator_for("cartpole", "balance", None, 2).n_threads == 2  # given: kept
        one = sampling.evaluate("cartpole", "balance", policy, 20, seed=5, max_episode_steps=200)
        with sampling.mujoco_threads(3):
            assert simulator.simulator_for("cartpole", "balance", None, None).n_threads == 3
        assert simulator.simulator_for("cartpole", "balance", None, None).n_threads == 1
    assert simulator.simulator_for("cartpole", "balance", None, None).n_threads == 2
    np.testing.assert_array_equal(one[0], two[0])
    np.testing.assert_array_equal(one[1], two[1])
    assert len(set(two[1])) > 1  # episodes of different lengths: the lockstep bookkeeping ran
    with pytest.raises(ValueError, match="n_threads"):
        with sampling.mujoco_threads(0):
            pass


def test_a_unit_steps_mujoco_on_one_thread():
    from tatl_mj.experiments.run import determinism

    with determinism.one_thread():
        assert simulator.simulator_for("pendulum", "swingup", None, None).n_threads == 1
    assert simulator.simulator_for("pendulum", "swingup", None, None).n_threads == 2


def test_a_policy_that_collects_does_not_disturb_the_collection():
    # collect() and evaluate() reuse one environment per task, reseeded; a policy that
    # itself collects or evaluates on the same task must get its own.
    def push(states):  # falls within a few dozen steps: new episodes start between calls
        return np.zeros(len(states), np.int64)

    def nosy(states):
        sampling.collect("cartpole", "balance", 50, seed=99)
        sampling.evaluate("cartpole", "balance", lambda s: np.zeros((len(s), 1)), 2, seed=98, max_episode_steps=5)
        return push(states)

    plain = sampling.collect("cartpole", "balance", 400, seed=5, policy=push, n_parallel=8)
    assert plain.last.sum() > 8
    nested = sampling.collect("cartpole", "balance", 400, seed=5, policy=nosy, n_parallel=8)
    for name in ("states", "actions", "rewards", "next_states", "absorbing", "last"):
        np.testing.assert_array_equal(getattr(nested, name), getattr(plain, name))
    # The reseeded environment starts where a new one would.
    random = sampling.collect("cartpole", "balance", 300, seed=5)
    replay("cartpole", "balance", random, seed=5)


def test_bound_views_do_not_keep_batches_alive():
    # Every collect() makes its own batch; the simulator's cache of bound views
    # must not hold them (or their memory) after the call.
    import gc

    sim = simulator.simulator_for("cartpole", "balance", None, 2)
    gc.collect()
    cached = len(sim.views)  # the query batches', if any
    for _ in range(3):
        sampling.collect("cartpole", "balance", 200, seed=1)
    gc.collect()
    assert len(sim.views) == cached


def test_closed_loop_policy_balances_longer_than_random():
    def lean(states):  # push the cart under the falling pole
        return np.where(states[:, 2] + 0.5 * states[:, 3] > 0, 2, 0)

    tr = sampling.collect("cartpole", "balance", 3000, seed=1, policy=lean, n_parallel=8)
    np.testing.assert_array_equal(tr.actions, lean(tr.states))
    random = sampling.collect("cartpole", "balance", 3000, seed=1)
    assert tr.last.sum() * 5 < random.last.sum()
    replay("cartpole", "balance", tr, seed=1)


@pytest.mark.parametrize("domain,task", suite.ALL_TASKS)
def test_step_from_is_one_environment_step(domain, task):
    kwargs = QUIET.get((domain, task))
    tr = sampling.collect(domain, task, 60, seed=9, task_kwargs=kwargs, n_parallel=1)
    states = tr.states[~tr.absorbing][:20]
    if domain == "gridworld":
        states = states[np.any(states != suite.DOMAINS[domain].GOAL, axis=1)]
    actions = np.arange(len(states)) % len(suite.action_set(domain))
    got = sampling.step_from(domain, task, states, actions, task_kwargs=kwargs)
    again = sampling.step_from(domain, task, states, actions, task_kwargs=kwargs)
    np.testing.assert_array_equal(got, again)
    env = suite.load(domain, task, task_kwargs={**(kwargs or {}), "random": 0})
    holder = getattr(env, "physics", env)
    for s, a, g in zip(states, actions, got):
        env.reset()
        holder.set_state_vector(s)
        want = env.step(suite.action_set(domain)[a]).observation["state"]
        assert_close(g, want)


def test_time_varying_queries_are_batched_and_equal_its_environment_steps_exactly():
    # Every query is an episode's first step, which runs on the reset model, even
    # after the sampler's own environment has stepped the schedule on.
    kwargs = {"amplitude": 0.75}
    sim = simulator.simulator_for("pendulum", "swingup_timevarying", kwargs, 2)
    assert sim.batched_queries and not sim.fast
    sampling.collect("pendulum", "swingup_timevarying", 137, seed=3, task_kwargs=kwargs)
    rng = np.random.default_rng(0)
    states = np.column_stack([rng.uniform(-np.pi, np.pi, 40), rng.uniform(-12.0, 12.0, 40)])
    actions = rng.integers(3, size=40)
    got = sampling.step_from("pendulum", "swingup_timevarying", states, actions, task_kwargs=kwargs)
    env = suite.load("pendulum", "swingup_timevarying", task_kwargs={**kwargs, "random": 0})
    for s, a, g in zip(states, actions, got):
        env.reset()
        env.physics.set_state_vector(s)
        np.testing.assert_array_equal(g, env.step(suite.action_set("pendulum")[a]).observation["state"])


def test_step_from_divergence_returns_the_start_state():
    states = np.array([[0.0, 0.0, 0.0, 0.0], [0.0, 2e10, 0.0, 0.0]])
    got = sampling.step_from("cartpole", "balance", states, np.array([1, 1]))
    env = suite.load("cartpole", "balance", task_kwargs={"random": 0})
    env.reset()
    env.physics.set_state_vector(states[1])
    timestep = env.step(suite.action_set("cartpole")[1])
    assert env.diverged and timestep.discount == 0.0
    np.testing.assert_array_equal(got[1], states[1])
    assert got[0, 2] == 0.0 and np.all(np.isfinite(got))


def test_a_query_that_diverges_where_an_earlier_one_diverged_still_returns_its_start_state():
    # MuJoCo's bad-value checks reset the data, warning counts included, and then
    # count one: the query batch's slot that diverged before shows that same 1 after
    # diverging again, which a before/after comparison of counts would miss (and
    # answer with MuJoCo's reset state). Each call must see its own warnings.
    states = np.array([[0.0, 0.0, 0.0, 0.0], [0.0, 2e10, 0.0, 0.0]])
    for _ in range(3):
        got = sampling.step_from("cartpole", "balance", states, np.array([2, 1]))
        np.testing.assert_array_equal(got[1], states[1])
        assert got[0, 0] > 0.0  # the pushed cart moved: the other query stepped


def test_a_domain_with_dm_controls_own_after_reset_has_its_first_step_replayed(monkeypatch):
    # dm_control's after_reset runs forward with actuation disabled, leaving the
    # bicycle's speed servo an actuator_velocity of 0 for the first substep: the
    # sampler replays such a first step through the reset hooks, where a plain
    # step (right for the suite's own after_reset) would not match the environment.
    from dm_control.mujoco import engine

    from tatl_mj.suite import bicycle

    monkeypatch.setattr(bicycle.Physics, "after_reset", engine.Physics.after_reset)
    kwargs = QUIET[("bicycle", "balance")]
    sim = simulator.Simulator("bicycle", "balance", tuple(kwargs.items()), 1)
    assert sim.legacy_first
    env = suite.load("bicycle", "balance", task_kwargs={**kwargs, "random": 0})
    rng = np.random.default_rng(0)
    states, actions = [], rng.integers(len(sim.actions), size=40)
    for _start in range(len(actions)):
        env.reset()
        for _ in range(int(rng.integers(1, 30))):
            env.step(suite.action_set("bicycle")[int(rng.integers(len(sim.actions)))])
        states.append(env.physics.state_vector())
    expected = []
    for s, a in zip(states, actions):
        env.reset()
        env.physics.set_state_vector(s)
        expected.append(env.step(suite.action_set("bicycle")[a]).observation["state"])
    controls = sim.env.task.controls(sim.actions[actions], np.random.RandomState(0))
    ids = np.arange(len(states))
    got = {}
    for replayed in (True, False):
        sim.legacy_first = replayed
        batch = sim.new_batch(len(states))
        sim.place(batch, ids, *sim.physics.qpos_qvel_from(np.array(states)))
        got[replayed], diverged = sim.advance(batch, ids, controls, np.ones(len(ids), bool))
        assert not diverged.any()
    np.testing.assert_array_equal(got[True], np.array(expected))
    assert not np.array_equal(got[False], np.array(expected))


def test_a_diverging_first_substep_is_reported():
    # A first substep replayed through the reset hooks (a domain with dm_control's
    # own after_reset; here the bicycle's) reports a warning there, which must end
    # the episode like any other.
    states = np.array([[0.0, 0.0, 0.0, 0.0], [0.0, 2e10, 0.0, 0.0]])
    sim = simulator.simulator_for("bicycle", "balance", None, 2)
    batch = sim.new_batch(2)
    sim.place(batch, np.arange(2), *sim.physics.qpos_qvel_from(states))
    assert not sim.first_substep(batch.state[0])
    assert sim.first_substep(batch.state[1])
    got = sampling.step_from("bicycle", "balance", states, np.array([1, 1]))
    np.testing.assert_array_equal(got[1], states[1])
    assert np.all(np.isfinite(got)) and not np.array_equal(got[0], states[0])


@pytest.mark.parametrize("domain,task", [("cartpole", "balance"), ("pendulum", "swingup_timevarying")])
def test_evaluate_matches_environment_returns(domain, task):
    gain = np.array([[1.0, 1.0, 20.0, 3.0]]) if domain == "cartpole" else np.array([[-2.0, -1.0]])

    def policy(states):
        return np.clip(states @ gain.T, -20.0, 20.0)

    returns, lengths = sampling.evaluate(domain, task, policy, 4, seed=7, max_episode_steps=120)
    assert returns.shape == lengths.shape == (4,)
    # Batched: the successive resets of one task seeded 7. Stepped through
    # environments (a model that changes every step): one per episode, seeded (7, i).
    shared = suite.load(domain, task, task_kwargs={"random": 7})
    for i in range(4):
        env = (
            shared
            if sampling.is_batched(domain, task)
            else suite.load(domain, task, task_kwargs={"random": np.random.RandomState([7, i])})
        )
        timestep, total, steps = env.reset(), 0.0, 0
        while not timestep.last() and steps < 120:
            timestep = env.step(policy(timestep.observation["state"][None])[0])
            total += timestep.reward
            steps += 1
        assert (total, steps) == (returns[i], lengths[i])


def test_time_varying_policies_run_in_lockstep_on_the_environments_own_steps():
    # One model a step, edited as the schedule says, serves every live episode (they all
    # start together); each policy's episodes are its environments' own, exactly.
    kwargs = {"amplitude": 0.75}
    assert simulator.simulator_for("pendulum", "swingup_timevarying", kwargs, 2).step_env is not None
    gains = [np.array([[-2.0, -1.0]]), np.array([[-8.0, -2.0]])]
    policies = [lambda s, g=g: np.clip(s @ g.T, -4.0, 4.0) for g in gains]
    got = sampling.evaluate_policies("pendulum", "swingup_timevarying", policies, 3, 5, kwargs)
    for policy, (returns, lengths) in zip(policies, got):
        for i in range(3):
            env = suite.load(
                "pendulum", "swingup_timevarying", task_kwargs={**kwargs, "random": np.random.RandomState([5, i])}
            )
            timestep, total, steps = env.reset(), 0.0, 0
            while not timestep.last():
                timestep = env.step(policy(timestep.observation["state"][None])[0])
                total, steps = total + timestep.reward, steps + 1
            assert (total, steps) == (returns[i], lengths[i]) and steps > 100


def _tv_greedy(seed: int, epsilon: float = 0.3):
    from tatl_mj.transfer.features import make_features
    from tatl_mj.transfer.fqi import LinearQ
    from tatl_mj.transfer.methods.target_fqi import EpsilonGreedy

    basis = {"kind": "rbf", "centers": 25, "low": [-3.0, -8.0], "high": [3.0, 8.0], "sigma": [0.6, 1.5]}
    features = make_features({**basis, "periodic": [True, False]}, 2)
    q = LinearQ(features, np.random.default_rng(5).normal(size=(3, features.size(2))))
    return EpsilonGreedy(q, epsilon, np.random.default_rng(seed))


@pytest.mark.parametrize("policy_kind", ["random", "epsilon-greedy"])
@pytest.mark.parametrize("n,steps", [(1234, 200), (300, 150)])
def test_time_varying_collections_run_in_lockstep_on_the_environments_own_steps(monkeypatch, policy_kind, n, steps):
    # The plain loop: one environment seeded 17, episode after episode, one action a call
    # (random ones drawn one at a time from default_rng(17)); the last episode cut at n.
    kwargs = {"amplitude": 0.5}
    lockstep = []
    scheduled = collection._collect_scheduled
    monkeypatch.setattr(
        collection, "_collect_scheduled", lambda *a, **k: lockstep.append(scheduled(*a, **k)) or lockstep[-1]
    )
    if policy_kind == "random":
        rng = np.random.default_rng(17)
        reference, policy = (lambda s: np.array([rng.integers(3)])), None
    else:
        reference, policy = _tv_greedy(9), _tv_greedy(9)
    env = suite.load("pendulum", "swingup_timevarying", task_kwargs={**kwargs, "random": 17})
    want = sampling.policy_transitions(env, reference, n, np.asarray(suite.action_set("pendulum")), steps)
    got = sampling.collect("pendulum", "swingup_timevarying", n, 17, policy, kwargs, max_episode_steps=steps)
    assert len(lockstep) == 1 and lockstep[0] is not None  # the lockstep path ran
    assert_same_transitions(got, want)
    assert int(got.last.sum()) == -(-n // steps)
    if policy is not None:  # the same draws, so the generator is where the plain loop leaves it
        assert policy.rng.bit_generator.state == reference.rng.bit_generator.state


def test_a_time_varying_collection_whose_episode_ends_early_runs_the_plain_loop(monkeypatch):
    # Later calls' draws depend on where earlier episodes ended, so lockstep gives up.
    kwargs = {"amplitude": 0.5}
    sim = simulator.simulator_for("pendulum", "swingup_timevarying", kwargs, 2)
    monkeypatch.setattr(sim.env.task, "batch_absorbing", lambda states: np.abs(states[:, 1]) > 3.0)
    results = []
    scheduled = collection._collect_scheduled
    monkeypatch.setattr(
        collection, "_collect_scheduled", lambda *a, **k: results.append(scheduled(*a, **k)) or results[-1]
    )
    policy, reference = _tv_greedy(4, epsilon=0.5), _tv_greedy(4, epsilon=0.5)
    env = suite.load("pendulum", "swingup_timevarying", task_kwargs={**kwargs, "random": 2})
    want = sampling.policy_transitions(env, reference, 700, np.asarray(suite.action_set("pendulum")), 200)
    got = sampling.collect("pendulum", "swingup_timevarying", 700, 2, policy, kwargs, max_episode_steps=200)
    assert results == [None]
    assert_same_transitions(got, want)
    assert policy.rng.bit_generator.state == reference.rng.bit_generator.state


def steer_into_lean(gain):
    """A bicycle policy (torque from roll and roll rate): low gains fall, at varied times."""
    return lambda s: np.clip(gain * (s[:, 2:3] + 0.25 * s[:, 3:4]), -2.0, 2.0)


def evaluated_noise(monkeypatch, policy, n_episodes, seed, max_episode_steps):
    """evaluate() on the noisy bicycle: (returns, lengths, each episode's CG offsets by step).

    Rows of the controls calls come in lockstep order (live episodes in order, step
    after step), so the lengths say which episode each row is.
    """
    from tatl_mj.suite import bicycle

    rows = []
    controls, controls_each = bicycle.Task.controls, bicycle.Task.controls_each

    def recorded(self, values, random):
        ctrl = controls(self, values, random)
        rows.append(ctrl[:, 1].copy())
        return ctrl

    def recorded_each(self, values, randoms):
        ctrl = controls_each(self, values, randoms)
        rows.append(ctrl[:, 1].copy())
        return ctrl

    with monkeypatch.context() as patch:
        patch.setattr(bicycle.Task, "controls", recorded)
        patch.setattr(bicycle.Task, "controls_each", recorded_each)
        returns, lengths = sampling.evaluate(
            "bicycle", "balance", policy, n_episodes, seed, max_episode_steps=max_episode_steps
        )
    offsets = np.concatenate(rows)
    assert len(offsets) == lengths.sum()
    per_step = np.split(offsets, np.cumsum([(lengths > t).sum() for t in range(lengths.max())])[:-1])
    noise = [
        np.array([step[(lengths[:i] > t).sum()] for t, step in enumerate(per_step[: lengths[i]])])
        for i in range(n_episodes)
    ]
    return returns, lengths, noise


def test_evaluation_rider_noise_is_each_episodes_own(monkeypatch):
    # Common random numbers: two policies evaluated with one seed give every episode
    # the same rider noise at every step both are alive, though their episodes end at
    # different times; known answer, episode i's stream is child i of
    # SeedSequence(seed)'s second child (evaluation.evaluation_randoms).
    seed, n, cg_noise = 3, 6, suite.bicycle.DEFAULT_CG_NOISE
    _, weak, weak_noise = evaluated_noise(monkeypatch, steer_into_lean(4.0), n, seed, 300)
    _, strong, strong_noise = evaluated_noise(monkeypatch, steer_into_lean(12.0), n, seed, 300)
    assert len(set(weak)) > 2 and not np.array_equal(weak, strong)  # episodes end apart
    for i in range(n):
        both = min(weak[i], strong[i])
        np.testing.assert_array_equal(weak_noise[i][:both], strong_noise[i][:both], err_msg=f"episode {i}")
        stream = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(1, i)))
        expected = stream.uniform(-cg_noise, cg_noise, size=max(weak[i], strong[i]))
        np.testing.assert_array_equal(weak_noise[i], expected[: weak[i]], err_msg=f"episode {i}")
        np.testing.assert_array_equal(strong_noise[i], expected[: strong[i]], err_msg=f"episode {i}")


def test_an_evaluation_episode_does_not_depend_on_the_batch(monkeypatch):
    # Episode 0 starts from the same first reset alone or with 4 more episodes (some
    # of which fall before it): its noise, states, return and length are the same.
    seeing = []

    def policy(states):
        seeing.append(states[0].copy())  # episode 0 is the first row while it lives
        return steer_into_lean(6.0)(states)

    alone = evaluated_noise(monkeypatch, policy, 1, 11, 400)
    states_alone, seeing[:] = np.array(seeing), []
    batch = evaluated_noise(monkeypatch, policy, 5, 11, 400)
    lengths = batch[1]
    assert lengths.min() < lengths[0] < 400  # others end before episode 0, which falls
    assert (alone[0][0], alone[1][0]) == (batch[0][0], lengths[0])
    np.testing.assert_array_equal(alone[2][0], batch[2][0])
    np.testing.assert_array_equal(states_alone, np.array(seeing)[: lengths[0]])


@pytest.mark.parametrize("domain,task", BATCHED_TASKS)
def test_evaluation_without_noise_draws_nothing_and_is_the_environment_loop(domain, task, monkeypatch):
    # Without control noise, evaluate() is what it was: one controls call a step for all
    # live episodes, with random=None (nothing drawn), and each episode the environment
    # loop over the successive resets of the task seeded with the seed.
    kwargs = QUIET.get((domain, task))
    env = suite.load(domain, task, task_kwargs={**(kwargs or {}), "random": 9})
    actions = np.asarray(suite.action_set(domain), np.float64)

    def policy(states):  # varied, deterministic actions: episodes end at different times
        return actions[(np.abs(np.floor(37.0 * states.sum(axis=1))) % len(actions)).astype(int)]

    randoms = []
    controls = type(env.task).controls

    def recorded(self, values, random):
        randoms.append(random)
        return controls(self, values, random)

    monkeypatch.setattr(type(env.task), "controls", recorded)
    monkeypatch.setattr(type(env.task), "control_noise", False)  # as before the override
    returns, lengths = sampling.evaluate(domain, task, policy, 5, seed=9, task_kwargs=kwargs, max_episode_steps=150)
    assert len(randoms) == lengths.max() and all(r is None for r in randoms)
    for i in range(5):
        timestep, total, steps = env.reset(), 0.0, 0
        while not timestep.last() and steps < 150:
            timestep = env.step(policy(timestep.observation["state"][None])[0])
            total += timestep.reward
            steps += 1
        assert (total, steps) == (returns[i], lengths[i]), i


def test_memory_is_contiguous_arrays():
    tracemalloc.start()
    tr = sampling.collect("cartpole", "balance", 100_000, seed=0, n_parallel=512)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    for name in ("states", "next_states", "rewards", "actions"):
        assert getattr(tr, name).flags.c_contiguous
    size = sum(getattr(tr, f).nbytes for f in ("states", "actions", "rewards", "next_states", "absorbing", "last"))
    assert size == 100_000 * 82
    assert peak < 4 * size, peak  # 10^6 transitions: well under 1 GB


@pytest.mark.parametrize(
    "kwargs,field",
    [
        ({"n_transitions": 0}, "n_transitions"),
        ({"n_threads": 0}, "n_threads"),
        ({"n_parallel": 0}, "n_parallel"),
        ({"max_episode_steps": 0}, "max_episode_steps"),
        ({"task_kwargs": {"random": 1}}, "random"),
        ({"policy": lambda s: np.full(len(s), 3)}, "action indices"),
        ({"policy": lambda s: np.zeros(len(s) + 1, int)}, "policy"),
    ],
)
def test_bad_input_names_the_field(kwargs, field):
    args = {"n_transitions": 50, "seed": 0, **kwargs}
    with pytest.raises(ValueError, match=field):
        sampling.collect("cartpole", "balance", **args)


def test_unknown_names_and_bad_states_raise():
    with pytest.raises(ValueError, match="valid domains"):
        sampling.collect("carpole", "balance", 10, seed=0)
    with pytest.raises(ValueError, match="columns"):
        sampling.step_from("cartpole", "balance", np.zeros((2, 3)), np.zeros(2, int))
    with pytest.raises(ValueError, match="action indices"):
        sampling.step_from("cartpole", "balance", np.zeros((2, 4)), np.array([0, 5]))
    with pytest.raises(ValueError, match=r"\(3, 1\) action values"):
        sampling.evaluate("cartpole", "balance", lambda s: np.zeros((len(s), 2)), 3, seed=0)
    # The grid world's actions are indices, not moves: the message says so.
    with pytest.raises(ValueError, match=r"\(3,\) action indices in 0..3 for gridworld"):
        sampling.evaluate("gridworld", "windy", lambda s: np.zeros((len(s), 2)), 3, seed=0, max_episode_steps=5)


def test_bench_prints_json_lines_with_the_summary_last(capsys):
    import argparse
    import json

    from tatl_mj import bench

    parser = argparse.ArgumentParser()
    bench.add_arguments(parser)
    args = parser.parse_args(
        [
            "--json",
            "--domains",
            "cartpole",
            "--seconds",
            "0.05",
            "--repeats",
            "2",
            "--memory-transitions",
            "3000",
            "--fqi-transitions",
            "0",
            "--render-frames",
            "0",
            "--vector-envs",
            "3",
        ]
    )
    assert bench.run(args) == 0
    records = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    paths = {r["path"] for r in records if r["kind"] == "steps"}
    has_gymnasium = importlib.util.find_spec("gymnasium") is not None
    assert paths == {"dm_control", "dm_control_floor", "sampler", "rollout"} | (
        {"gymnasium"} if has_gymnasium else set()
    )
    for record in (r for r in records if r["kind"] == "steps"):  # the faster of two runs
        assert record["repeats"] == 2 and record["slowest_steps_per_s"] <= record["steps_per_s"]
    summary = records[-1]
    assert summary["kind"] == "summary"
    for key in ("sampler_steps_per_s", "dm_control_steps_per_s", "rollout_steps_per_s", "rollout_vs_dm_control"):
        assert summary[key] > 0
    assert summary["dm_control_vs_floor"] == pytest.approx(
        summary["dm_control_steps_per_s"] / summary["dm_control_floor_steps_per_s"]
    )
    by_path = {r["path"]: r for r in records if r["kind"] == "steps"}
    pairs = np.divide(by_path["sampler"]["each_steps_per_s"], by_path["rollout"]["each_steps_per_s"])
    assert len(pairs) == 2 and summary["sampler_vs_rollout_paired"] == pytest.approx(pairs.mean())
    if has_gymnasium:
        peer = next(r for r in records if r.get("path") == "gymnasium")
        assert peer["env_id"] == "CartPole-v1" and peer["steps"] >= 100
        assert summary["sampler_vs_gymnasium"] == pytest.approx(summary["sampler_steps_per_s"] / peer["steps_per_s"])
        assert summary["rollout_vs_gymnasium"] == pytest.approx(summary["rollout_steps_per_s"] / peer["steps_per_s"])
    assert summary["machine"]["mujoco"] and summary["memory_peak_mb"] > 0
    if has_gymnasium:  # the vector envs of cartpole's one task, beside SyncVectorEnv and raw rollout
        vector = {r["path"]: r for r in records if r["kind"] == "vector"}
        assert set(vector) == {"vector", "sync_vector", "rollout"} and vector["vector"]["num_envs"] == 3
        figures = summary["vector"]["cartpole/balance"]
        assert figures["vector_vs_rollout"] == pytest.approx(
            vector["vector"]["steps_per_s"] / vector["rollout"]["steps_per_s"]
        )
        assert figures["vector_vs_sync_vector"] == pytest.approx(
            vector["vector"]["steps_per_s"] / vector["sync_vector"]["steps_per_s"]
        )
    assert bench.run(parser.parse_args(["--domains", "cartpol"])) == 2
    assert bench.run(parser.parse_args(["--vector-tasks", "cartpole/swing"])) == 2
    assert bench.run(parser.parse_args(["--repeats", "0"])) == 2
    assert "--repeats must be >= 1" in capsys.readouterr().out


@pytest.mark.parametrize("mode", ["distinct", "resample"])
def test_bench_times_vector_envs_with_contexts_beside_rollout_over_their_models(capsys, mode):
    import argparse
    import json

    pytest.importorskip("gymnasium")
    from tatl_mj import bench

    parser = argparse.ArgumentParser()
    bench.add_arguments(parser)
    args = ["--json", "--domains", "pendulum", "--vector-tasks", "pendulum/swingup_timevarying", "--seconds", "0.05"]
    args += ["--repeats", "1", "--memory-transitions", "0", "--fqi-transitions", "0", "--render-frames", "0"]
    assert bench.run(parser.parse_args(args + ["--vector-envs", "3", "--contexts", mode])) == 0
    records = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    vector = {r["path"]: r for r in records if r["kind"] == "vector"}
    assert (
        set(vector) == {"vector", "rollout"} and vector["rollout"]["contexts"] == mode == vector["vector"]["contexts"]
    )
    figures = records[-1]["vector"]["pendulum/swingup_timevarying"]
    assert figures["contexts"] == mode and figures["vector_vs_rollout"] == pytest.approx(
        vector["vector"]["steps_per_s"] / vector["rollout"]["steps_per_s"]
    )
    with pytest.raises(SystemExit):
        parser.parse_args(["--contexts", "some"])


def test_bench_notes_a_missing_gymnasium_and_times_the_rest(capsys, monkeypatch):
    import argparse

    from tatl_mj import bench

    monkeypatch.setitem(sys.modules, "gymnasium", None)  # import gymnasium now raises ImportError
    parser = argparse.ArgumentParser()
    bench.add_arguments(parser)
    args = parser.parse_args(
        [
            "--domains",
            "pendulum",
            "--seconds",
            "0.05",
            "--memory-transitions",
            "0",
            "--fqi-transitions",
            "0",
            "--render-frames",
            "0",
        ]
    )
    assert bench.run(args) == 0
    out = capsys.readouterr().out
    assert "gymnasium for pendulum: skipped (gymnasium is not installed" in out
    assert "vector for pendulum/swingup_timevarying: skipped (gymnasium is not installed" in out
    assert "pendulum          sampler" in out and "Gymnasium's loop" not in out


def test_transitions_save_and_load_round_trip(tmp_path):
    tr = sampling.collect("pendulum", "swingup", 250, seed=2)
    tr.save(str(tmp_path / "t.npz"))
    back = type(tr).load(str(tmp_path / "t.npz"))
    for name in ("states", "actions", "rewards", "next_states", "absorbing", "last"):
        np.testing.assert_array_equal(getattr(back, name), getattr(tr, name))
        assert getattr(back, name).dtype == getattr(tr, name).dtype


# --- Several control steps in one call (random actions) ------------------------------


def test_steps_refused_by_mujoco_are_stepped_one_at_a_time(monkeypatch):
    # advance_steps gives up (MuJoCo warned) and puts the simulations back:
    # the pass then steps once, with the random streams as they were.
    refused = []

    def refuse(self, batch, ids, controls):
        refused.append(len(controls))
        return None

    monkeypatch.setattr(simulator.Simulator, "advance_steps", refuse)
    got = sampling.collect("bicycle", "balance", 800, seed=3)
    assert refused
    monkeypatch.setattr(schedule, "MOST_STEPS", 1)
    assert_same_transitions(got, sampling.collect("bicycle", "balance", 800, seed=3))


def test_advance_steps_gives_up_on_a_diverging_simulation():
    sim = simulator.simulator_for("cartpole", "balance", None, 2)
    batch = sim.new_batch(2)
    ids = np.arange(2)
    sim.place(batch, ids, *sim.physics.qpos_qvel_from(np.array([[0.0, 0.0, 0.1, 0.0], [0.0, 2e10, 0.0, 0.0]])))
    rows = batch.state.copy()
    assert sim.advance_steps(batch, ids, np.zeros((4, 2, 1))) is None
    np.testing.assert_array_equal(batch.state, rows)
    # Without the diverging one, 4 steps in one call are 4 single steps.
    one = sim.new_batch(1)
    one.state[0] = rows[0]
    states = sim.advance_steps(one, ids[:1], np.zeros((4, 1, 1)))
    single = sim.new_batch(1)
    single.state[0] = rows[0]
    for k in range(4):
        step, _ = sim.advance(single, ids[:1], np.zeros((1, 1)), np.array([False]))
        np.testing.assert_array_equal(states[k], step)
    np.testing.assert_array_equal(one.state[0], single.state[0])


@pytest.mark.parametrize("domain,task", BATCHED_TASKS)
def test_controls_draw_row_after_row(domain, task):
    # The multi-step path draws the noise of K steps in one call.
    env = suite.load(domain, task, task_kwargs={"random": 0})
    values = np.asarray(suite.action_set(domain), np.float64)[np.arange(12) % len(suite.action_set(domain))]
    values = values.reshape(12, -1)
    whole = env.task.controls(values, np.random.RandomState(4))
    random = np.random.RandomState(4)
    parts = np.concatenate([env.task.controls(values[i : i + 5], random) for i in range(0, 12, 5)])
    np.testing.assert_array_equal(whole, parts)


GRID, RANDOM_START = ("gridworld", "windy"), {"random_start": True}


@pytest.mark.parametrize("max_episode_steps", [None, 7, 150])
def test_the_grid_loops_on_its_known_table_equal_stepping_its_environment(max_episode_steps):
    # collect() and evaluate() look the grid's steps up in its known model; the
    # environment loops they replace must give the same numbers, random starts,
    # random actions and a policy drawing its own exploration included.
    sim = simulator.simulator_for(*GRID, RANDOM_START, 2)
    assert sim.table is not None

    def explorer(seed):
        rng = np.random.default_rng(seed)

        def policy(states):
            greedy = np.where(states[:, 1] < 8, 3, 0)
            return np.where(rng.random(len(states)) < 0.2, rng.integers(4, size=len(states)), greedy)

        return policy

    def both(fn, explore, **kwargs):  # (on the table, stepping the environment)
        def once():
            policy = {"policy": explorer(kwargs["seed"])} if explore else {}
            return fn(*GRID, **kwargs, **policy, task_kwargs=RANDOM_START, max_episode_steps=max_episode_steps)

        on_table = once()
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(sim, "table", None)
            return on_table, once()

    for seed in (0, 3):
        pairs = [
            both(sampling.collect, False, n_transitions=3000, seed=seed),
            both(sampling.collect, True, n_transitions=2000, seed=seed),
        ]
        for table, stepped in pairs:
            for field in ("states", "actions", "rewards", "next_states", "absorbing", "last"):
                got, want = getattr(table, field), getattr(stepped, field)
                assert got.dtype == want.dtype
                np.testing.assert_array_equal(got, want)
        table, stepped = both(sampling.evaluate, True, n_episodes=20, seed=seed)
        for got, want in zip(table, stepped):
            assert got.dtype == want.dtype
            np.testing.assert_array_equal(got, want)


def test_a_grid_policy_collected_on_its_table_equals_policy_transitions_in_its_environment():
    # The pipeline's policy stream on the grid uses collect() (the table); it must equal
    # the environment loop policy_transitions runs, from the same seeded environment.
    def policy(states):
        return np.where(states[:, 1] < 8, 3, 0)

    got = sampling.collect(*GRID, 1500, seed=11, policy=policy, task_kwargs=RANDOM_START, max_episode_steps=40)
    env = suite.load(*GRID, task_kwargs={**RANDOM_START, "random": 11})
    want = sampling.policy_transitions(env, policy, 1500, np.arange(4), max_episode_steps=40)
    for field in FIELDS:
        np.testing.assert_array_equal(getattr(got, field), getattr(want, field))


def _grid_epsilon_greedy(seed: int, cells: bool):
    from tatl_mj.transfer.features import make_features
    from tatl_mj.transfer.fqi import LinearQ
    from tatl_mj.transfer.methods.target_fqi import EpsilonGreedy

    features = make_features({"kind": "onehot", "n_rows": 10, "n_cols": 10}, 2)
    q = LinearQ(features, np.random.default_rng(8).normal(size=(4, features.size(2))))
    return EpsilonGreedy(q, 0.3, np.random.default_rng(seed), cells=cells)


@pytest.mark.parametrize("cells", [False, True])
def test_a_drawing_policy_on_the_grid_table_draws_first_and_takes_the_same_actions(monkeypatch, cells):
    # On the table, a DrawingPolicy's draws are made for every step first and each step
    # answered from its row; a plain call a step (the same policy behind a lambda,
    # which is not a DrawingPolicy) must give the same transitions and leave its
    # generator where the draws-first path leaves it.
    drawing, reference = _grid_epsilon_greedy(5, cells), _grid_epsilon_greedy(5, cells)
    assert isinstance(drawing, DrawingPolicy) and not isinstance(lambda s: reference(s), DrawingPolicy)
    kwargs = dict(task_kwargs=RANDOM_START, max_episode_steps=60)
    answered, act = [], type(drawing).act
    monkeypatch.setattr(
        type(drawing), "act", lambda self, states, draws: answered.append(1) or act(self, states, draws)
    )
    got = sampling.collect(*GRID, 2500, seed=4, policy=drawing, **kwargs)
    assert len(answered) == 2500  # the draws-first path, a row a step
    want = sampling.collect(*GRID, 2500, seed=4, policy=lambda s: reference(s), **kwargs)
    for field in FIELDS:
        np.testing.assert_array_equal(getattr(got, field), getattr(want, field))
    assert drawing.rng.bit_generator.state == reference.rng.bit_generator.state
    explored = got.actions != _grid_epsilon_greedy(5, cells).q.greedy(got.states)
    assert 0.1 < explored.mean() < 0.4  # epsilon 0.3, a quarter of explorations greedy by chance


def test_a_state_policy_on_the_grid_table_is_asked_once_a_cell_for_the_same_transitions():
    asked = []

    def policy(states):
        asked.append(tuple(states[0]))
        return np.where(states[:, 1] < 8, 3, np.where(states[:, 0] > 4, 0, 1))

    kwargs = dict(task_kwargs=RANDOM_START, max_episode_steps=40)
    got = sampling.collect(*GRID, 3000, seed=2, policy=StatePolicy(policy), **kwargs)
    assert len(asked) == len(set(asked)) == len(np.unique(got.states, axis=0))
    asked.clear()
    want = sampling.collect(*GRID, 3000, seed=2, policy=policy, **kwargs)
    assert len(asked) == 3000  # a call a step
    for field in FIELDS:
        np.testing.assert_array_equal(getattr(got, field), getattr(want, field))


def test_the_grid_table_refuses_what_its_environment_refuses():
    with pytest.raises(ValueError, match="gridworld action must be one of"):
        sampling.evaluate("gridworld", "windy", lambda s: np.full(len(s), 1.5), 3, seed=0, max_episode_steps=5)


@pytest.mark.parametrize("domain,task", [("bicycle", "balance"), ("cartpole", "balance")])
def test_evaluate_policies_gives_each_policy_what_it_gets_alone(domain, task):
    """One lockstep batch of three policies: each one's returns and lengths, and every state
    it is asked about, equal its own evaluation (the bicycle's rider noise included)."""
    column = 2 if domain == "bicycle" else 1  # roll, or the pole's angle
    limit = 2.0 if domain == "bicycle" else 1.0
    calls: dict[int, list] = {0: [], 1: [], 2: []}

    def feedback(gain, b):
        def policy(states):
            calls[b].append(np.array(states))
            return np.clip(gain * states[:, column : column + 1], -limit, limit)

        return policy

    policies = [feedback(g, b) for b, g in enumerate((0.0, 5.0, 30.0))]
    together = sampling.evaluate_policies(domain, task, policies, 3, seed=5, max_episode_steps=150)
    joint_calls = {b: list(c) for b, c in calls.items()}
    for b, policy in enumerate(policies):
        calls[b].clear()
        returns, lengths = sampling.evaluate(domain, task, policy, 3, seed=5, max_episode_steps=150)
        np.testing.assert_array_equal(together[b][0], returns)
        np.testing.assert_array_equal(together[b][1], lengths)
        assert len(calls[b]) == len(joint_calls[b])
        for alone, joint in zip(calls[b], joint_calls[b]):
            np.testing.assert_array_equal(alone, joint)
    assert len({tuple(r[1]) for r in together}) > 1  # the gains lead to different episodes
