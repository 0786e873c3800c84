"""A given policy scored on a spec's conditions and seeds, as the spec's methods are (``tatl evaluate``).

Each (condition, seed) unit evaluates the policy on the target with the very protocol
a method's learning curve uses (``evaluation.target_returns`` from the seed's
evaluation starts, ``derive_seed(seed, stream, "evaluation")``), and normalises its
mean return between the seed's uniformly random policy (``source_unit.random_return``,
no source work) and the preset's ``reference_return`` (``verdicts.normalised``): the
same two returns that seed's methods are judged with.

A policy is a batched callable, ``states (N, d) -> action values (N, m)`` (indices
``(N,)`` for a target that takes them), the contract of a method's learned policy
(``tatl_mj.transfer.method.Policy``). With ``context_in_observation`` it gets each
state with the condition's context values appended (``suite.check_context``'s keys
in order), as ``TatlEnv(context_in_observation=True)`` and the vector env give them.

The output folder holds one record per unit (``units/CONDITION/seed-S.json``, written
atomically and reused by a rerun), the manifest of what was evaluated
(``evaluation.json``), and the scores (``scores.json``, ``scores.csv``).
"""

from __future__ import annotations

import csv
import dataclasses
import io
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tatl_mj import suite
from tatl_mj.experiments.results import records, verdicts
from tatl_mj.experiments.run import determinism, lock
from tatl_mj.experiments.run.evaluation import target_returns
from tatl_mj.experiments.run.source_unit import random_return
from tatl_mj.experiments.spec import ExperimentSpec, Preset, SpecError, conditions

MANIFEST = "evaluation.json"
SCORES = "scores.json"
TABLE = "scores.csv"
UNITS = "units"
IDENTITY = ("spec_hash", "preset", "policy", "context_in_observation", "transitions")
"""The manifest's fields a rerun into the same folder must share (its seeds and command may differ)."""
COLUMNS = ("experiment", "condition", "seed", "mean_return", "random_return", "reference_return", "normalised")


class EvaluationError(ValueError):
    """What cannot be evaluated, or a folder that holds another evaluation; one line."""


def checked_preset(spec: ExperimentSpec, name: str) -> Preset:
    """The spec's preset ``name``, which must give a reference return to normalise with."""
    try:
        preset = spec.preset(name)
    except SpecError as error:
        raise EvaluationError(str(error)) from None
    if preset.reference_return is None:
        raise EvaluationError(
            f"{spec.path}: presets.{name} has no reference_return, so no normalised score; "
            "use a preset that has one (e.g. paper)"
        )
    return preset


def context_values(condition: ExperimentSpec) -> np.ndarray:
    """The condition's context values in the task's key order: what an observation with the
    context appended ends with (``TatlEnv(context_in_observation=True)``)."""
    target = condition.target
    values = suite.check_context(target.domain, target.task, {}, target.task_kwargs)
    return np.array(list(values.values()), dtype=np.float64)


def with_context(policy: Callable, values: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """``policy`` called on each state with ``values`` appended."""

    def decide(states: np.ndarray) -> np.ndarray:
        states = np.asarray(states, dtype=np.float64)
        return policy(np.concatenate([states, np.broadcast_to(values, (len(states), len(values)))], axis=1))

    return decide


def score_unit(
    condition: ExperimentSpec, preset: Preset, policy: Callable, seed: int, context_in_observation: bool = False
) -> dict:
    """One condition and seed: the policy's per-episode returns, the random and reference returns
    and the normalised score of its mean return (None where the reference is not above random)."""
    if context_in_observation:
        policy = with_context(policy, context_values(condition))
    with determinism.one_thread():  # as a method unit evaluates, so a record's return is reproduced
        returns, lengths = target_returns(
            condition, preset, policy, determinism.derive_seed(seed, condition.stream_name, "evaluation")
        )
        random = random_return(condition, preset, seed)
    mean = float(np.mean(returns))
    assert preset.reference_return is not None  # checked_preset
    try:
        score: float | None = float(verdicts.normalised(np.array(mean), random, preset.reference_return))
    except ValueError:
        score = None
    return {
        "experiment": condition.name,
        "condition": dict(condition.condition),
        "seed": int(seed),
        "mean_return": mean,
        "returns": [float(r) for r in returns],
        "steps": [int(n) for n in lengths],
        "random_return": float(random),
        "reference_return": float(preset.reference_return),
        "normalised": score,
    }


@dataclasses.dataclass(frozen=True)
class Evaluation:
    """What ``evaluate`` scores: a spec's conditions under one preset, on ``seeds``."""

    spec: ExperimentSpec
    preset_name: str
    seeds: Sequence[int]
    policy: Callable
    manifest: dict  # what was evaluated (the policy's identity, the spec's path and hash, ...)
    context_in_observation: bool = False


def evaluate(job: Evaluation, out: str | Path, progress: Callable[[str], None] | None = None) -> dict:
    """Scores ``job.policy`` on every condition and seed into folder ``out`` (resumable: a unit
    already recorded there is read back, not recomputed); returns scores.json's content."""
    preset = checked_preset(job.spec, job.preset_name)
    root = Path(out)
    with lock.hold(root):
        manifest = _claim(root, job)
        rows = []
        for condition in conditions(job.spec):
            for seed in job.seeds:
                path = root / UNITS / condition.name / f"seed-{seed}.json"
                row = _recorded(path)
                if row is None:
                    row = score_unit(condition, preset, job.policy, seed, job.context_in_observation)
                    records.write_json(path, row)
                    if progress is not None:
                        progress(f"{condition.name} seed {seed}: normalised {_text(row['normalised'])}")
                rows.append(row)
        scores = {"manifest": manifest, "rows": rows}
        records.write_json(root / SCORES, scores)
        records.write_atomic(root / TABLE, table(rows).encode())
    return scores


def _claim(root: Path, job: Evaluation) -> dict:
    """Writes the manifest; refuses a folder whose manifest is another evaluation's."""
    manifest = {**job.manifest, "seeds": [int(s) for s in job.seeds]}
    try:
        before = records.read_json(root / MANIFEST)
    except FileNotFoundError:
        before = None
    if isinstance(before, dict):
        differ = [k for k in IDENTITY if before.get(k) != manifest.get(k)]
        if differ:
            raise EvaluationError(
                f"{root} holds another evaluation (its {differ[0]} is {before.get(differ[0])!r}, "
                f"here {manifest.get(differ[0])!r}); use another --out"
            )
    records.write_json(root / MANIFEST, manifest)
    return manifest


def _recorded(path: Path) -> dict | None:
    """A unit's record written by an earlier run, or None (missing or unreadable: recomputed)."""
    try:
        row = records.read_json(path)
    except (FileNotFoundError, records.RecordError):
        return None
    return row if isinstance(row, dict) and all(k in row for k in COLUMNS) else None


def _text(value: float | None) -> str:
    return "n/a (reference not above random)" if value is None else f"{value:.3f}"


def table(rows: Iterable[dict]) -> str:
    """The rows as CSV, one per condition and seed; the condition as ``key=value`` pairs."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(COLUMNS)
    for row in rows:
        condition = ";".join(f"{k}={v}" for k, v in row["condition"].items())
        writer.writerow([row["experiment"], condition] + [_cell(row[k]) for k in COLUMNS[2:]])
    return buffer.getvalue()


def _cell(value: Any) -> Any:
    return "" if value is None else value


def read_scores(folder: str | Path) -> dict:
    """A ``tatl evaluate`` folder's scores.json; RecordError or FileNotFoundError naming it."""
    path = Path(folder) / SCORES
    if not path.exists():
        raise FileNotFoundError(f"{path} not found: run `tatl evaluate SPEC --policy ... --out {folder}` first")
    scores = records.read_json(path)
    if not isinstance(scores, dict) or not isinstance(scores.get("rows"), list) or "manifest" not in scores:
        raise records.RecordError(f"{path}: not a tatl evaluate scores file (no manifest and rows)")
    return scores


def is_evaluation(folder: str | Path) -> bool:
    """Whether ``folder`` is a ``tatl evaluate`` output folder (it has a manifest)."""
    return (Path(folder) / MANIFEST).exists()


__all__ = [
    "Evaluation",
    "EvaluationError",
    "checked_preset",
    "context_values",
    "evaluate",
    "is_evaluation",
    "read_scores",
    "score_unit",
    "table",
    "with_context",
]
