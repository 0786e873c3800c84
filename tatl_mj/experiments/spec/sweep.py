"""A sweep's conditions: the experiments a spec with a ``[sweep]`` stands for, one per combination."""

from __future__ import annotations

import dataclasses
from typing import Any

from tatl_mj.experiments.spec.schema import ExperimentSpec


def _value_text(value: Any) -> str:
    return repr(value) if not isinstance(value, str) else value


def conditions(spec: ExperimentSpec) -> list[ExperimentSpec]:
    """The experiments a spec stands for: itself, or one per combination of its sweep's values,
    named ``NAME.PARAM-VALUE[.PARAM-VALUE]`` with those target task_kwargs, kept apart in
    their own records and resumable like any experiment."""
    if not spec.sweep:
        return [spec]
    names = list(spec.sweep)
    grids = [[]]  # type: list[list[tuple[str, Any]]]
    for name in names:
        grids = [g + [(name, v)] for g in grids for v in spec.sweep[name]]
    out = []
    for combo in grids:
        suffix = ".".join(f"{k}-{_value_text(v)}" for k, v in combo)
        target = dataclasses.replace(spec.target, task_kwargs={**spec.target.task_kwargs, **dict(combo)})
        name, condition, streams = f"{spec.name}.{suffix}", dict(combo), spec.stream_name
        out.append(dataclasses.replace(spec, name=name, target=target, sweep={}, condition=condition, streams=streams))
    return out
