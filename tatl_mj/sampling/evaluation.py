"""Evaluation: returns and lengths of a policy's episodes, all in lockstep.

Start states are the successive resets of the task seeded with ``seed``
(:func:`start_states` gives them without running the episodes); the noise the
task's controls draw is each episode's own (:func:`evaluation_randoms`), so
policies evaluated with one seed see common random numbers.
"""

from __future__ import annotations

import functools
from typing import Any, Callable, Sequence

import numpy as np

from tatl_mj.sampling.checks import ValuePolicy, check_values
from tatl_mj.sampling.simulator import (
    SUBSTEPS,
    Simulator,
    controls_each,
    episode_simulator,
    observed_state,
    simulator_for,
)
from tatl_mj.validation import integer

Joint = Callable[[list[int], list[np.ndarray]], list[np.ndarray]]
"""``joint(blocks, states)``: for each listed policy (its index into ``policies``), its action
values for its live episodes' states, exactly what calling it alone gives (e.g. several
policies' decisions sharing one source rollout)."""

Visitor = Callable[[int, np.ndarray, np.ndarray, Callable[[np.ndarray], np.ndarray], Callable[[int], Any]], None]
"""``visitor(step, live, values, rows, random_of)``, called before each lockstep control step:
the live simulations (policy b's episode i is b * n + i), their action values, ``rows(ids)``
the MuJoCo ``mjSTATE_INTEGRATION`` rows of simulations ``ids`` (copies) and ``random_of(id)``
the stream a simulation's controls draw from (None: they draw nothing). It only reads:
what it is handed is copied or not used again (the premises' visits)."""


def evaluate(
    domain: str,
    task: str,
    policy: ValuePolicy,
    n_episodes: int,
    seed: int,
    task_kwargs: dict[str, Any] | None = None,
    max_episode_steps: int | None = None,
    n_threads: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Undiscounted returns (n,) and lengths (n,) of ``policy`` over ``n_episodes``.

    All episodes run in lockstep from the task's start distribution (the
    successive resets of the task seeded with ``seed``); ``policy`` maps the
    (N, d) states of the live episodes to (N, action_dim) action values.

    The noise the task's controls draw (the bicycle's rider) is each episode's
    own: episode i's controls draw from its own Generator
    (:func:`evaluation_randoms`), one call a step, so the noise of its step t
    depends on ``seed``, i and t alone, not on which other episodes still run:
    methods evaluated with one seed see common random numbers. Controls without
    noise draw nothing (``random=None``), one call for all live episodes.
    """
    (result,) = evaluate_policies(domain, task, [policy], n_episodes, seed, task_kwargs, max_episode_steps, n_threads)
    return result


def evaluate_policies(
    domain: str,
    task: str,
    policies: Sequence[ValuePolicy],
    n_episodes: int,
    seed: int,
    task_kwargs: dict[str, Any] | None = None,
    max_episode_steps: int | None = None,
    n_threads: int | None = None,
    joint: Joint | None = None,
    visitor: Visitor | None = None,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """:func:`evaluate` of each of ``policies`` with the same ``seed``, all in one lockstep batch.

    Each policy's episodes are the ones ``evaluate`` runs for it alone: the same
    starts and noise, and it is called with the same states in the same order;
    only the per-step work of stepping them is shared (a learning curve's budgets
    are evaluated together). ``joint`` answers all policies' calls of a step at
    once (default: each policy in turn). Tasks stepped through their environment
    or their known table evaluate the policies one after another, but for one
    whose model depends on the step alone (``model_for_step``), whose episodes
    run in lockstep on that step's model.
    """
    n_episodes = integer("", "n_episodes", n_episodes, 1)
    if not policies:
        raise ValueError("evaluate_policies needs at least one policy")
    sim = episode_simulator(domain, task, task_kwargs, n_threads, max_episode_steps)
    if joint is None:
        joint = one_by_one(policies)
    if not sim.fast and sim.step_env is not None and not sim.env.task.control_noise:
        returns, lengths = _evaluate_scheduled(sim, joint, len(policies), n_episodes, seed, max_episode_steps, visitor)
        return [(returns[b], lengths[b]) for b in range(len(policies))]
    if not sim.fast:
        # Each policy through ``joint`` (what calling it alone gives), so an observer sees these calls too.
        return [
            _evaluate_loop(sim, functools.partial(_through, joint, b), n_episodes, seed, max_episode_steps)
            for b in range(len(policies))
        ]
    limit = sim.step_limit(max_episode_steps)
    if not np.isfinite(limit):
        raise ValueError(f"{domain}/{task} has no time limit: give max_episode_steps")
    returns, lengths = _evaluate_batch(sim, joint, len(policies), n_episodes, seed, limit, visitor)
    return [(returns[b], lengths[b]) for b in range(len(policies))]


def one_by_one(policies: Sequence[ValuePolicy]) -> Joint:
    """The plain :data:`Joint`: each listed policy called on its own states, in turn."""
    return functools.partial(_call_each, policies)


def _through(joint: Joint, block: int, states: np.ndarray) -> np.ndarray:
    return joint([block], [states])[0]


def _call_each(policies: Sequence[ValuePolicy], blocks: list[int], states: list[np.ndarray]) -> list[np.ndarray]:
    return [policies[b](s) for b, s in zip(blocks, states)]


def _evaluate_batch(
    sim: Simulator,
    joint: Joint,
    n_policies: int,
    n_episodes: int,
    seed: int,
    limit: float,
    visitor: Visitor | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(K, n) returns and lengths: simulation b * n + i is policy b's episode i."""
    with sim.seeded_env(seed) as env:
        task_obj = env.task
        # Every policy's episode i starts where and draws what evaluate's episode i does.
        randoms = None
        if task_obj.control_noise:
            randoms = [r for _ in range(n_policies) for r in evaluation_randoms(seed, n_episodes)]

        def controls(values: np.ndarray, live: np.ndarray) -> np.ndarray:
            return controls_each(task_obj, values, None if randoms is None else [randoms[i] for i in live])

        starts = task_obj.start_configurations(env.physics, n_episodes)
        random_of = (lambda i: None) if randoms is None else randoms.__getitem__
        return _lockstep(sim, task_obj, joint, n_policies, starts, controls, limit, visit=(visitor, random_of))


def _evaluate_scheduled(
    sim: Simulator,
    joint: Joint,
    n_policies: int,
    n_episodes: int,
    seed: int,
    max_episode_steps: int | None,
    visitor: Visitor | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(K, n) returns and lengths of :func:`_evaluate_loop`'s episodes, batched: a task whose
    model depends on the step alone (``model_for_step``), its episodes all at the same step.

    The starts are the environments' seeded ``(seed, i)``; each control step runs every live
    episode on the one model of that step, so the steps are the environments' own.
    """
    envs = [sim.make_env(np.random.RandomState([seed, i])) for i in range(n_episodes)]
    for env in envs:
        env.reset()
    starts = tuple(np.stack([np.array(getattr(env.physics.data, f)) for env in envs]) for f in ("qpos", "qvel"))
    task_obj = sim.env.task
    batch = sim.new_batch(n_policies * n_episodes)
    limit = min(sim.step_limit(None), np.inf if max_episode_steps is None else max_episode_steps)
    controls = lambda values, live: task_obj.controls(values, None)  # noqa: E731
    models = sim.scheduled_models(batch)
    return _lockstep(
        sim, task_obj, joint, n_policies, starts, controls, limit, batch, models, (visitor, lambda i: None)
    )


def _lockstep(
    sim: Simulator,
    task_obj: Any,
    joint: Joint,
    n_policies: int,
    starts: tuple[np.ndarray, np.ndarray],
    controls: Callable[[np.ndarray, np.ndarray], np.ndarray],
    limit: float,
    batch: Any = None,
    model_for: Callable[[int], None] | None = None,
    visit: tuple[Visitor | None, Callable[[int], Any]] = (None, lambda i: None),
) -> tuple[np.ndarray, np.ndarray]:
    """Every policy's episodes of ``task_obj`` from ``starts`` (qpos, qvel of episode i), all in
    one batch: simulation b * n + i is policy b's episode i. ``controls(values, live)`` gives the live
    rows' controls; ``model_for(step)``, where given, sets the batch's model for that step;
    ``visit``: a :data:`Visitor` (None: none) and each simulation's random stream."""
    n_episodes = len(starts[0])
    total = n_policies * n_episodes
    batch = sim.new_batch(total) if batch is None else batch
    live = np.arange(total)
    qpos, qvel = np.tile(starts[0], (n_policies, 1)), np.tile(starts[1], (n_policies, 1))
    sim.place(batch, live, qpos, qvel)
    states = sim.physics.states_from(qpos, qvel)
    returns = np.zeros(total)
    lengths = np.zeros(total, np.int64)
    step = 0
    while len(live):
        values = _joint_values(joint, sim, live, states, n_episodes)
        if visit[0] is not None:
            visit[0](step, live, values, lambda ids: np.array(batch.state[ids]), visit[1])
        if model_for is not None:
            model_for(step)
        next_states, diverged = sim.advance(batch, live, controls(values, live), lengths[live] == 0)
        rewards = np.where(diverged, 0.0, task_obj.batch_reward(next_states))
        returns[live] += rewards
        lengths[live] += 1
        step += 1
        ended = diverged | task_obj.batch_absorbing(next_states) | (lengths[live] >= limit)
        live, states = live[~ended], next_states[~ended]
    return returns.reshape(n_policies, n_episodes), lengths.reshape(n_policies, n_episodes)


def _joint_values(joint: Joint, sim: Simulator, live: np.ndarray, states: np.ndarray, n_episodes: int) -> np.ndarray:
    """The live episodes' action values: each policy called (through ``joint``) on its own rows."""
    owner = live // n_episodes  # live is sorted, so each policy's rows are one run
    blocks, starts = np.unique(owner, return_index=True)
    ends = [*starts[1:], len(live)]
    answers = joint([int(b) for b in blocks], [states[a:z] for a, z in zip(starts, ends)])
    return np.concatenate([check_values(v, z - a, sim) for v, a, z in zip(answers, starts, ends)])


def evaluation_randoms(seed: int, n_episodes: int) -> list[np.random.Generator]:
    """Each evaluation episode's Generator for its controls' noise.

    Episode i's is child i of ``SeedSequence(seed)``'s second child (collect()'s
    noise starts from the first), whatever ``n_episodes``: its stream depends on
    the seed and its number only, and is apart from collect()'s with the same seed.
    """
    parent = np.random.SeedSequence(seed, spawn_key=(1,))
    return [np.random.default_rng(child) for child in parent.spawn(n_episodes)]


def _evaluate_loop(
    sim: Simulator,
    policy: ValuePolicy,
    n_episodes: int,
    seed: int,
    max_episode_steps: int | None,
) -> tuple[np.ndarray, np.ndarray]:
    """Lockstep over one environment per episode, seeded ``(seed, i)``: its start
    and any noise are episode i's own, as on the batched path (from another stream).
    A task with a known table (:class:`Table`) takes the same starts and policy calls,
    each live episode's step looked up in the table."""
    envs = [sim.make_env(np.random.RandomState([seed, i])) for i in range(n_episodes)]
    firsts = [e.reset() for e in envs]
    if sim.table is None:
        states, step = np.stack([observed_state(f) for f in firsts]), _env_step(sim, envs)
        limit = np.inf if max_episode_steps is None else max_episode_steps
    else:
        cells = np.array([sim.table.cell(f) for f in firsts], np.int64)
        states, step = sim.table.states[cells], _table_step(sim, envs, cells)
        limit = sim.table.episode_limit(max_episode_steps)
    returns = np.zeros(n_episodes)
    lengths = np.zeros(n_episodes, np.int64)
    live = np.arange(n_episodes)
    while len(live):
        values = check_values(policy(states[live]), len(live), sim)
        rewards, states[live], ended = step(live, values)
        returns[live] += rewards
        lengths[live] += 1
        live = live[~(ended | (lengths[live] >= limit))]
    if sim.table is None:
        SUBSTEPS[sim.key] += int(lengths.sum()) * sim.substeps
    return returns, lengths


LockstepStep = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]
"""``step(live, values)`` -> the live episodes' (rewards, next states, whether the task ended them)."""


def _env_step(sim: Simulator, envs: list) -> LockstepStep:
    """Each live episode's step through its own environment."""

    def step(live: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        timesteps = [envs[i].step(values[j]) for j, i in enumerate(live)]
        rewards = np.array([timestep.reward for timestep in timesteps], np.float64)
        next_states = np.stack([observed_state(timestep) for timestep in timesteps])
        return rewards, next_states, np.array([timestep.last() for timestep in timesteps], bool)

    return step


def _table_step(sim: Simulator, envs: list, cells: np.ndarray) -> LockstepStep:
    """Each live episode's step looked up in the task's table; ``cells`` (each episode's) in place."""
    table = sim.table
    assert table is not None

    def step(live: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        values = values[:, 0]
        valid = np.isfinite(values) & (values >= 0) & (values < len(sim.actions))
        valid[valid] = values[valid] == np.floor(values[valid])
        if not valid.all():  # the environment's own error for an action it refuses
            j = int(np.argmin(valid))
            envs[live[j]].step(values[j : j + 1])
            raise ValueError(f"{sim.domain} action must be an index in 0..{len(sim.actions) - 1}, got {values[j]}")
        c, a = cells[live], values.astype(np.int64)
        cells[live] = table.next_state[c, a]
        return table.reward[c, a], table.states[cells[live]], table.absorbing[c, a]

    return step


def start_states(
    domain: str, task: str, n_episodes: int, seed: int, task_kwargs: dict[str, Any] | None = None
) -> np.ndarray:
    """(n, d) the start states of ``evaluate(domain, task, ..., n_episodes, seed)``'s episodes.

    So a model can be scored from exactly the states a real rollout starts from
    (Algorithm 2 compares U_M and U_Mhat from the same starts).
    """
    n = integer("", "n_episodes", n_episodes, 1)
    sim = simulator_for(domain, task, task_kwargs, 1)
    if not sim.fast:
        envs = [sim.make_env(np.random.RandomState([seed, i])) for i in range(n)]
        return np.stack([observed_state(e.reset()) for e in envs])
    with sim.seeded_env(seed) as env:
        qpos, qvel = env.task.start_configurations(env.physics, n)
        return sim.physics.states_from(qpos, qvel)
