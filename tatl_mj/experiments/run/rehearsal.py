"""A user's method rehearsed on a tiny problem of each target before any source work.

A plug-in whose policy answers in the wrong shape or type would otherwise fail in its first
method unit, after its source unit's work (tens of seconds on the paper preset). Before a
run starts, :func:`rehearse` builds one tiny problem per pair of tasks (a one-iteration
source Q on a few hundred samples, a short target stream, the spec's mapping on few
samples: nothing of it is recorded), has each user method learn from a few target samples,
and calls the policy once on a few target states. A policy that raises, or returns other than
the target takes (``(n, m)`` or, for one actuator, ``(n,)`` finite action values; ``(n,)``
action indices where the target takes indices), stops the run in one line.

Only the policy's answer is judged: a ``learn`` that fails on so little data, or a tiny
problem the spec's mapping cannot be learned from, is left to the run itself.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np

from tatl_mj.description import TaskDescription
from tatl_mj.experiments.run import determinism, method_unit, sides, source_unit
from tatl_mj.experiments.spec import ExperimentSpec

STATES = 5
"""Target states the policy is called on."""
SAMPLES = 40
"""Target samples the method learns from, and the mapping at most."""


class RehearsalError(ValueError):
    """A user's policy that answers other than its target takes; one line naming the method."""


def _tiny(spec: ExperimentSpec, preset: str) -> tuple[ExperimentSpec, Any]:
    """The spec with a one-iteration source learner, and its preset cut to a few samples."""
    settings = spec.preset(preset)
    tiny = dataclasses.replace(
        settings,
        source_samples=min(settings.source_samples, 400),
        alignment_samples=min(settings.alignment_samples, SAMPLES),
        target_budgets=(min(settings.target_budgets[0], SAMPLES),),
        evaluation_episodes=1,
        evaluation_steps=min(settings.evaluation_steps, 10),
    )
    learner = dataclasses.replace(spec.source_learning, iterations=1)
    return dataclasses.replace(spec, source_learning=learner), tiny


def expected(target: TaskDescription) -> str:
    """What a policy must return for ``target``, in words."""
    if target.discrete:
        return f"(n,) integer action indices in 0..{target.n_actions - 1}"
    m = target.action_values.shape[1]
    return f"(n, {m}) finite action values" + (" or (n,)" if m == 1 else "")


def answer_problem(values: Any, n: int, target: TaskDescription) -> str | None:
    """Why ``values`` (a policy's answer for ``n`` states) is not what ``target`` takes, or None."""
    try:
        v = np.asarray(values)
    except Exception as error:  # noqa: BLE001 - the user's object may refuse anything
        return f"an answer numpy cannot read ({type(error).__name__})"
    if v.dtype.kind not in "biuf":
        return f"an array of dtype {v.dtype}"
    if target.discrete:
        whole = v.shape == (n,) and (v.dtype.kind in "biu" or bool(np.all(np.mod(v, 1) == 0)))
        ok = whole and bool(np.all((v >= 0) & (v < target.n_actions)))
        return None if ok else f"shape {v.shape} with values {np.unique(v)[:5].tolist()}"
    m = target.action_values.shape[1]
    if v.shape != (n, m) and not (m == 1 and v.shape == (n,)):
        return f"shape {v.shape}"
    return None if bool(np.all(np.isfinite(v))) else "values that are not finite"


def _tiny_problem(spec: ExperimentSpec, preset: str, seed: int) -> tuple[Any, Any, Any] | None:
    """(spec, preset, artefacts) of a tiny problem, or None where the spec's phases fail on it."""
    small, tiny = _tiny(spec, preset)
    try:
        return small, tiny, source_unit.learn_source(small, tiny, seed)
    except Exception:  # noqa: BLE001 - a mapping that needs more data: the run itself will tell
        return None


def rehearse(specs: list[ExperimentSpec], preset: str, methods: Mapping[str, Any], seed: int = 0) -> None:
    """Each of ``methods`` (name -> method object, or {experiment: object}) learns on a tiny
    problem of each pair of tasks in ``specs`` and its policy is called on a few target
    states; :class:`RehearsalError` naming the method and what the target takes, where not."""
    if not methods:
        return
    seen: set[tuple] = set()
    for spec in specs:
        key = (spec.source.domain, spec.source.task, spec.target.domain, spec.target.task, spec.mapping.kind)
        if key in seen:
            continue
        seen.add(key)
        built = _tiny_problem(spec, preset, seed)
        if built is None:
            continue
        small, tiny, artifacts = built
        for name, transfer in methods.items():
            obj = transfer[spec.name] if isinstance(transfer, dict) else transfer
            _one(small, tiny, artifacts, name, obj, seed)


def _one(spec: ExperimentSpec, tiny: Any, artifacts: Any, name: str, transfer: Any, seed: int) -> None:
    with determinism.one_thread():
        try:
            policy = method_unit.learned_policy(spec, tiny, seed, transfer, artifacts, SAMPLES)
        except Exception:  # noqa: BLE001 - too little data for it, perhaps: the run will tell
            return
        target = sides.description_of(spec.target)
        states = artifacts.target_stream.states[:STATES]
        try:
            values = policy(states)
        except Exception as error:  # noqa: BLE001 - the user's policy may raise anything
            problem = f"raised {type(error).__name__}: {error}"
        else:
            found = answer_problem(values, len(states), target)
            problem = None if found is None else f"returned {found}"
    if problem is not None:
        raise RehearsalError(
            f"method {name!r}: its policy, learned on a tiny problem of {spec.name} and called on {len(states)} "
            f"target states, {problem}; {spec.target.domain}/{spec.target.task} takes {expected(target)}"
        )


__all__ = ["RehearsalError", "answer_problem", "expected", "rehearse"]
