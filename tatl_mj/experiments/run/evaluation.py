"""Evaluation on the target task: a policy's per-episode returns (``target_returns``), a
learning curve's policies side by side in one lockstep batch (``evaluate_curve``), and the
steadiness of their episodes (``per_episode``, ``steadiness``).

Policies that can decide for one another's states together say so through the method
contract's hook (``tatl_mj.transfer.method.joint_decisions``); the others are called one
by one.
"""

from __future__ import annotations

from typing import Callable, Protocol

import numpy as np

from tatl_mj import sampling
from tatl_mj.description import TaskDescription
from tatl_mj.experiments.spec import ExperimentSpec, Preset
from tatl_mj.transfer import method


class Observer(Protocol):
    """What ``evaluate_curve`` asks of an observer (``run.premises.PremiseObserver``)."""

    @property
    def active(self) -> bool: ...

    def joint(self, together: method.JointDecisions) -> method.JointDecisions: ...

    def visitor(self, step: int, live: np.ndarray, values: np.ndarray, rows: Callable, random_of: Callable) -> None: ...


def target_returns(spec: ExperimentSpec, preset: Preset, policy: Callable, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-episode returns and lengths of ``policy`` on the target task."""
    return _on_target(spec, preset, [policy], seed)[0]


def _on_target(
    spec: ExperimentSpec,
    preset: Preset,
    policies: list[Callable],
    seed: int,
    joint: sampling.Joint | None = None,
    visitor: sampling.Visitor | None = None,
) -> list[tuple[np.ndarray, np.ndarray]]:
    target = spec.target
    return sampling.evaluate_policies(
        target.domain,
        target.task,
        policies,
        preset.evaluation_episodes,
        seed,
        task_kwargs=target.task_kwargs,
        max_episode_steps=preset.evaluation_steps,
        joint=joint,
        visitor=visitor,
    )


def evaluate_curve(
    spec: ExperimentSpec,
    preset: Preset,
    policies: list[Callable],
    seed: int,
    record: bool,
    observer: Observer | None = None,
) -> list[tuple[np.ndarray, np.ndarray, list | None]]:
    """Each policy's per-episode returns and lengths on the target task, from the same starts,
    all in one lockstep batch (a learning curve's budgets), and with ``record`` each one's
    per-episode (states, action values) lists for steadiness. ``observer`` (the premises')
    answers its TA-TL policies' decisions with the same values and keeps what it sees."""
    together = method.joint_decisions(policies) or sampling.one_by_one(policies)
    visitor = None
    if observer is not None and observer.active:
        together, visitor = observer.joint(together), observer.visitor
    calls: list[list[tuple[np.ndarray, np.ndarray]]] = [[] for _ in policies]

    def joint(blocks: list[int], states: list[np.ndarray]) -> list[np.ndarray]:
        values = together(blocks, states)
        if record:
            for b, s, v in zip(blocks, states, values):
                calls[b].append((np.array(s, dtype=np.float64), np.array(v, dtype=np.float64)))
        return values

    results = _on_target(spec, preset, policies, seed, joint, visitor)
    return [(r, n, per_episode(c, n) if record else None) for (r, n), c in zip(results, calls)]


def per_episode(
    calls: list[tuple[np.ndarray, np.ndarray]], lengths: np.ndarray
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Each episode's states (T_i, d) and action values (T_i, m), in step order, from a
    policy's lockstep calls: at step t its live episodes are, in order, those whose
    length exceeds t."""
    rows: list[list[int]] = [[] for _ in lengths]
    for t in range(len(calls)):
        for j, i in enumerate(np.flatnonzero(lengths > t)):
            rows[i].append(j)
    states = [np.stack([calls[t][0][j] for t, j in enumerate(r)]) for r in rows]
    values = [np.stack([np.atleast_1d(calls[t][1][j]) for t, j in enumerate(r)]) for r in rows]
    return states, values


def steadiness(description: TaskDescription, states: list[np.ndarray], values: list[np.ndarray]) -> dict:
    """Per episode: the RMS over its steps of each ``description.steadiness`` state entry (named
    ``<entry>_rms``, in the state's units) and the mean absolute actuator value after clipping
    (``mean_abs_action``). The steps are those the episode lasted: its balanced time, where a
    fall ends it."""
    out: dict[str, list[float]] = {}
    for name in description.steadiness:
        k = description.state_names.index(name)
        out[f"{name}_rms"] = [float(np.sqrt(np.mean(s[:, k] ** 2))) for s in states]
    if not description.discrete:
        low, high = description.action_low, description.action_high
        out["mean_abs_action"] = [float(np.mean(np.abs(np.clip(v, low, high)))) for v in values]
    return out
