"""summary.json's content as frozen dataclasses: what the tables, the figures, the credit maps,
the export, the reference sets and the scripts read (:func:`read`, :meth:`Summary.from_json`).

The writer (:mod:`tatl_mj.experiments.results.summary`) stays dict-based and decides the file's
bytes; these classes only read it. A summary of an older schema is upgraded first
(``records.upgrade``, the one place older files are read): fields are read as the current
schema has them, and those absent here are absent in the schema too (no normalised scores
without a reference return, no verdicts without normalised scores, no steadiness where the
target declares none). Values keep their JSON types (a count read as an int stays one), so
what is printed from them does not change.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from tatl_mj.experiments.results import verdicts
from tatl_mj.experiments.results.records import UNKNOWN_KERNELS, read_record


@dataclasses.dataclass(frozen=True)
class Interval:
    """A point estimate with its 95% interval; None where it could not be had (NaN)."""

    value: float | None
    low: float | None
    high: float | None

    @classmethod
    def from_json(cls, data: Mapping[str, Any] | None) -> Interval | None:
        return None if data is None else cls(data["value"], data["low"], data["high"])

    def bounds(self) -> tuple[float, float, float]:
        """``(value, low, high)`` as floats: NaN without a value, the value where a bound is missing."""
        value = np.nan if self.value is None else self.value
        return value, value if self.low is None else self.low, value if self.high is None else self.high


@dataclasses.dataclass(frozen=True)
class Curve:
    """One method's learning curves, [seed][budget] on its seeds (``samples`` the budgets)."""

    samples: tuple[int, ...]
    mean_return: tuple[tuple[float, ...], ...]
    target_transitions: tuple[tuple[float, ...], ...]
    rollout_transitions: tuple[tuple[float, ...], ...]
    samples_used: tuple[tuple[float, ...], ...] | None = None
    """The shared samples kept at each budget (TA-TL: its apprentice's); None in an older summary."""

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Curve:
        def rows(key: str) -> tuple[tuple[float, ...], ...]:
            return tuple(tuple(row) for row in data[key])

        return cls(
            tuple(data["samples"]),
            rows("mean_return"),
            rows("target_transitions"),
            rows("rollout_transitions"),
            rows("samples_used") if "samples_used" in data else None,
        )

    def transitions(self, accounting: str, placed: bool = True) -> np.ndarray:
        """[seed][budget] transitions on an accounting (``verdicts.transitions``); ``placed``: a point
        that counted none stands at its budget."""
        return verdicts.transitions(
            self.target_transitions, self.rollout_transitions, accounting, self.samples if placed else None
        )


@dataclasses.dataclass(frozen=True)
class Survival:
    """Kaplan-Meier survival of a method's evaluation episodes to the cap at its largest budget."""

    steps: tuple[float, ...]
    probability: tuple[float, ...]
    at_cap: float
    episodes: int
    seeds: tuple[int, ...]


@dataclasses.dataclass(frozen=True)
class MethodSummary:
    """One method of one experiment: its curves and finals per finished seed, and (with a reference
    return) its normalised statistics."""

    seeds: tuple[int, ...]
    final_return: tuple[float, ...]
    curve: Curve
    data: str = ""
    final_steps: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    shared_from: Mapping[str, str] = dataclasses.field(default_factory=dict)
    normalised: tuple[tuple[float, ...], ...] | None = None
    iqm: tuple[Interval, ...] | None = None
    final_iqm: Interval | None = None
    efficiency: Interval | None = None
    efficiency_paper: Interval | None = None
    first_policy: Mapping[str, float] | None = None
    survival: Survival | None = None
    steadiness: Mapping[str, Interval] | None = None
    steadiness_seeds: tuple[int, ...] = ()
    premises: tuple[tuple[Mapping[str, float | None] | None, ...], ...] | None = None
    """[seed][budget] the premises measured at each point (None: none measured, or an older record)."""

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> MethodSummary:
        survival = data.get("survival")
        steadiness = data.get("steadiness")
        return cls(
            seeds=tuple(data["seeds"]),
            final_return=tuple(data["final_return"]),
            curve=Curve.from_json(data["curve"]),
            data=data.get("data", ""),
            final_steps=data.get("final_steps", {}),
            shared_from=data.get("shared_from", {}),
            normalised=None if "normalised" not in data else tuple(tuple(r) for r in data["normalised"]),
            iqm=None if "iqm" not in data else tuple(Interval.from_json(e) for e in data["iqm"]),  # type: ignore[misc]
            final_iqm=Interval.from_json(data.get("final_iqm")),
            efficiency=Interval.from_json(data.get("efficiency")),
            efficiency_paper=Interval.from_json(data.get("efficiency_paper")),
            first_policy=data.get("first_policy"),
            survival=None
            if survival is None
            else Survival(
                tuple(survival["steps"]),
                tuple(survival["probability"]),
                survival["at_cap"],
                survival["episodes"],
                tuple(survival["seeds"]),
            ),
            steadiness=None if steadiness is None else {k: Interval.from_json(v) for k, v in steadiness.items()},  # type: ignore[misc]
            steadiness_seeds=tuple(data.get("steadiness_seeds", ())),
            premises=None if data.get("premises") is None else tuple(tuple(row) for row in data["premises"]),
        )

    def rows(self, seeds: tuple[int, ...] | list[int]) -> list[int]:
        """The rows of ``seeds`` in this method's per-seed lists."""
        return [self.seeds.index(s) for s in seeds]


@dataclasses.dataclass(frozen=True)
class Answer:
    """One question of one pair as summary.json keeps it (``verdicts.Answer.as_dict``)."""

    probability: Interval
    seeds: Mapping[str, int]  # better, tied, worse
    verdict: str
    holm: bool | None = None  # absent on the paper's accounting: not in the family
    median_difference: Interval | None = None

    @classmethod
    def from_json(cls, data: Mapping[str, Any] | None) -> Answer | None:
        if not data:
            return None
        return cls(
            probability=Interval.from_json(data["probability"]),  # type: ignore[arg-type]
            seeds=data["seeds"],
            verdict=data["verdict"],
            holm=data.get("holm"),
            median_difference=Interval.from_json(data.get("median_difference")),
        )


@dataclasses.dataclass(frozen=True)
class PairVerdict:
    """One declared pair's verdicts (``verdicts.judge``): per question its answer, None where not asked."""

    method: str
    other: str
    role: str
    parents: bool
    final: Answer | None
    efficiency: Answer | None
    efficiency_paper: Answer | None

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> PairVerdict:
        return cls(
            method=data["method"],
            other=data["other"],
            role=data["role"],
            parents=bool(data.get("parents")),
            final=Answer.from_json(data.get(verdicts.FINAL)),
            efficiency=Answer.from_json(data.get(verdicts.EFFICIENCY)),
            efficiency_paper=Answer.from_json(data.get("efficiency_paper")),
        )

    def answer(self, question: str) -> Answer | None:
        return {verdicts.FINAL: self.final, verdicts.EFFICIENCY: self.efficiency}[question]


@dataclasses.dataclass(frozen=True)
class Experiment:
    """One experiment of a summary: its spec (as the run resolved it), methods and verdicts."""

    name: str
    spec: Mapping[str, Any]
    methods: Mapping[str, MethodSummary]
    source_seeds: tuple[int, ...]
    random_returns: tuple[float, ...] | None  # per source seed; None in a summary older than them
    reference_return: float | None = None
    mapping_target_samples: tuple[int, ...] = ()
    efficiency_range: tuple[float, float] | None = None
    families: Mapping[str, int] | None = None
    verdicts: tuple[PairVerdict, ...] | None = None  # None: no normalised scores, so no verdicts
    algorithm2_not_met: Mapping[str, list[int]] = dataclasses.field(default_factory=dict)

    @classmethod
    def from_json(cls, name: str, data: Mapping[str, Any]) -> Experiment:
        span = data.get("efficiency_range")
        judged = data.get("verdicts")
        return cls(
            name=name,
            spec=data.get("spec") or {},
            methods={m: MethodSummary.from_json(d) for m, d in data["methods"].items()},
            source_seeds=tuple(data.get("source_seeds", ())),
            random_returns=None if "random_returns" not in data else tuple(data["random_returns"]),
            reference_return=data.get("reference_return"),
            mapping_target_samples=tuple(data.get("mapping_target_samples", ())),
            efficiency_range=None if span is None else (span[0], span[1]),
            families=data.get("families"),
            verdicts=None if judged is None else tuple(PairVerdict.from_json(v) for v in judged),
            algorithm2_not_met=data.get("algorithm2_not_met") or {},
        )

    @property
    def title(self) -> str:
        return self.spec.get("title", self.spec.get("name", self.name))

    @property
    def spec_methods(self) -> Mapping[str, Any]:
        """The methods the spec lists, with their tables."""
        return self.spec.get("methods") or {}

    @property
    def random_by_seed(self) -> dict[int, float] | None:
        """The random policy's return per source seed (None in a summary older than them)."""
        return None if self.random_returns is None else dict(zip(self.source_seeds, self.random_returns))


@dataclasses.dataclass(frozen=True)
class AggregateRow:
    """One method's normalised final score across experiments (``summary.aggregate``)."""

    estimate: Interval
    experiments: int
    runs: int
    scores: tuple[float, ...]


@dataclasses.dataclass(frozen=True)
class Summary:
    """A run's summary.json."""

    preset: str
    seeds: list[int]
    methods: list[str]
    experiments: Mapping[str, Experiment]
    aggregate: Mapping[str, AggregateRow]
    kernels: Mapping[str, int]
    verdict_rule_version: int
    threshold_fraction: float
    reference_threshold: float
    versions: Mapping[str, Any]
    failures: list[Any]

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Summary:
        """From summary.json's content in the current schema (``records.upgrade`` reads older ones)."""
        return cls(
            preset=data["preset"],
            seeds=list(data["seeds"]),
            methods=list(data["methods"]),
            experiments={n: Experiment.from_json(n, e) for n, e in data["experiments"].items()},
            aggregate={
                m: AggregateRow(Interval.from_json(r), r["experiments"], r["runs"], tuple(r["scores"]))  # type: ignore[arg-type]
                for m, r in (data.get("aggregate") or {}).items()
            },
            kernels=data["kernels"],
            verdict_rule_version=data["verdict_rule_version"],
            threshold_fraction=data["threshold_fraction"],
            reference_threshold=data["reference_threshold"],
            versions=data.get("versions") or {},
            failures=list(data.get("failures") or []),
        )

    @property
    def known_kernels(self) -> dict[str, int]:
        """The run's sets of arithmetic kernels with their record counts, but records older than the field."""
        return {k: n for k, n in self.kernels.items() if k != UNKNOWN_KERNELS}


def read(path: str | Path) -> Summary:
    """A summary.json, upgraded from an older schema where it is one."""
    return Summary.from_json(read_record(path))


__all__ = [
    "AggregateRow",
    "Answer",
    "Curve",
    "Experiment",
    "Interval",
    "MethodSummary",
    "PairVerdict",
    "Summary",
    "Survival",
    "read",
]
