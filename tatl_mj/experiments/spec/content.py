"""What a spec's records depend on: its content (the settings as a dict, and their hash) and the
dynamics version of each task it uses."""

from __future__ import annotations

import dataclasses
import hashlib
import json

from tatl_mj.experiments.spec.schema import ExperimentSpec


def spec_to_dict(spec: ExperimentSpec) -> dict:
    """A JSON-able copy of the spec (for summary.json)."""
    return dataclasses.asdict(spec)


NOT_CONTENT = ("path", "title", "paper_claim", "paper", "best_baseline")
"""Spec fields that cannot change a record: where it was read from, its prose, the paper's
numbers, and the baseline its verdicts are read against (frozen after the tuning runs)."""


def content_hash(spec: ExperimentSpec | dict, preset: str | None = None) -> str:
    """The SHA-256 of a spec's content: its parsed, resolved settings (:func:`spec_to_dict`, or
    that dict as summary.json keeps it, but :data:`NOT_CONTENT`) as canonical JSON, not the
    file's bytes, so a reformatted spec, or one that reaches the same settings another way,
    keeps it. With ``preset`` (one the spec has), the other presets are left out: records of
    that preset depend on none of them."""
    table = spec_to_dict(spec) if isinstance(spec, ExperimentSpec) else dict(spec)
    table = {k: v for k, v in table.items() if k not in NOT_CONTENT}
    if preset is not None:
        table["presets"] = {preset: table["presets"][preset]}
    text = json.dumps(table, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


def dynamics_versions(spec: ExperimentSpec) -> dict[str, int]:
    """The dynamics version of each task the spec uses, by ``domain/task`` (source, then target)."""
    from tatl_mj import suite

    return {
        f"{side.domain}/{side.task}": suite.describe(side.domain, side.task, side.task_kwargs).dynamics_version
        for side in (spec.source, spec.target)
    }
