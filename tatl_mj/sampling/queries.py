"""One-step queries: the next states after one control step from given states."""

from __future__ import annotations

from typing import Any

import numpy as np

from tatl_mj.sampling.checks import check_indices, check_states, check_values
from tatl_mj.sampling.simulator import SUBSTEPS, Simulator, observed_state, simulator_for


def step_from(
    domain: str,
    task: str,
    states: np.ndarray,
    action_indices: np.ndarray,
    task_kwargs: dict[str, Any] | None = None,
    n_threads: int | None = None,
) -> np.ndarray:
    """Next states after one control step from each of ``states`` (N, d).

    Each start is put in place as ``set_state_vector`` does (a fresh reset,
    then the paper state), and ``action_indices`` (N,) index ``ACTIONS``.
    Controls that draw noise use a ``RandomState(0)``. A step that diverges
    returns its start state, as the environment does. A task with a known
    exact model (``suite.describe(...).known_model``) answers from it.
    """
    sim = simulator_for(domain, task, task_kwargs, n_threads)
    s = check_states(states)
    a = check_indices(action_indices, len(s), len(sim.actions))
    if not sim.batched_queries:
        return _step_from_env(sim, s, a)
    return _step_values(sim, s, sim.actions[a])


def step_values_from(
    domain: str,
    task: str,
    states: np.ndarray,
    action_values: np.ndarray,
    task_kwargs: dict[str, Any] | None = None,
    n_threads: int | None = None,
) -> np.ndarray:
    """Like :func:`step_from`, with actuator values (N, m) instead of action indices."""
    sim = simulator_for(domain, task, task_kwargs, n_threads)
    s = check_states(states)
    if not sim.fast:
        raise ValueError(f"{domain}/{task} is stepped through its environment; use step_from with action indices")
    return _step_values(sim, s, check_values(action_values, len(s), sim))


def _step_values(sim: Simulator, s: np.ndarray, values: np.ndarray) -> np.ndarray:
    if s.shape[1] != sim.physics.STATE_SIZE:
        raise ValueError(f"{sim.domain} states must have {sim.physics.STATE_SIZE} columns, got {s.shape[1]}")
    if len(s) == 0:
        return s.copy()
    batch = sim.query_batch(len(s))
    ids = np.arange(len(s))
    sim.place(batch, ids, *sim.physics.qpos_qvel_from(s))
    controls = sim.env.task.controls(values, _SeededOnUse(0))
    next_states, diverged = sim.advance(batch, ids, controls, np.ones(len(ids), bool))
    next_states[diverged] = s[diverged]
    return next_states


class _SeededOnUse:
    """``np.random.RandomState(seed)``, built on its first use.

    Most tasks' controls draw nothing, and building one costs about 0.13 ms, as
    much as the step itself (a horizon controller makes 10 such queries a decision).
    """

    def __init__(self, seed: int):
        self._seed = seed
        self._random: np.random.RandomState | None = None

    def __getattr__(self, name: str) -> Any:
        if self._random is None:
            self._random = np.random.RandomState(self._seed)
        return getattr(self._random, name)


def _step_from_env(sim: Simulator, s: np.ndarray, a: np.ndarray) -> np.ndarray:
    """One step per query through the environment, or the task's known exact model."""
    if sim.table is not None:
        return sim.table.states[sim.table.next_state[sim.table.cell_map.index(s), a]]
    env = sim.env
    target = getattr(env, "physics", env)  # whichever holds set_state_vector
    out = np.empty_like(s)
    for i in range(len(s)):
        env.reset()
        target.set_state_vector(s[i])
        out[i] = observed_state(env.step(sim.actions[a[i]]))
    SUBSTEPS[sim.key] += len(s) * sim.substeps
    return out
