"""Evaluation: returns and lengths of a policy's episodes, all in lockstep.

Start states are the successive resets of the task seeded with ``seed``
(:func:`start_states` gives them without running the episodes); the noise the
task's controls draw is each episode's own (:func:`evaluation_randoms`), so
policies evaluated with one seed see common random numbers.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from tatl_mj.sampling.checks import ValuePolicy, check_values
from tatl_mj.sampling.simulator import SUBSTEPS, Simulator, episode_simulator, observed_state, simulator_for
from tatl_mj.validation import integer


def evaluate(
    domain: str,
    task: str,
    policy: ValuePolicy,
    n_episodes: int,
    seed: int,
    task_kwargs: dict[str, Any] | None = None,
    max_episode_steps: int | None = None,
    n_threads: int = 2,
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
    n_episodes = integer("", "n_episodes", n_episodes, 1)
    sim = episode_simulator(domain, task, task_kwargs, n_threads, max_episode_steps)
    if not sim.fast:
        return _evaluate_loop(sim, policy, n_episodes, seed, max_episode_steps)
    limit = sim.step_limit(max_episode_steps)
    if not np.isfinite(limit):
        raise ValueError(f"{domain}/{task} has no time limit: give max_episode_steps")
    with sim.seeded_env(seed) as env:
        task_obj = env.task
        randoms = evaluation_randoms(seed, n_episodes) if task_obj.control_noise else None
        # Optional in the domain contract: each row's controls from its own stream at once.
        controls_each = getattr(task_obj, "controls_each", None)
        batch = sim.new_batch(n_episodes)
        live = np.arange(n_episodes)
        states = sim.start_episodes(batch, live, env)
        returns = np.zeros(n_episodes)
        lengths = np.zeros(n_episodes, np.int64)
        while len(live):
            values = check_values(policy(states), len(live), sim)
            if randoms is None:
                controls = task_obj.controls(values, None)
            elif controls_each is not None:  # the same draws in one call
                controls = controls_each(values, [randoms[i] for i in live])
            else:
                controls = np.concatenate(
                    [task_obj.controls(values[j : j + 1], randoms[i]) for j, i in enumerate(live)]
                )
            next_states, diverged = sim.advance(batch, live, controls, lengths[live] == 0)
            rewards = np.where(diverged, 0.0, task_obj.batch_reward(next_states))
            returns[live] += rewards
            lengths[live] += 1
            ended = diverged | task_obj.batch_absorbing(next_states) | (lengths[live] >= limit)
            live, states = live[~ended], next_states[~ended]
    return returns, lengths


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
