"""The verdict rule: the two questions asked of each pair an experiment compares, and how each
is judged (docs/protocol.md, "Verdicts", declares it with its reasons).

A pair is (method, other, role): a transfer method against its source-free **ablation**, against
itself on a **placebo** source, or any method against the experiment's frozen **best baseline**
(chosen on the tuning seeds by ``choose_best_baseline``). The spec declares them, from the roles
its methods declare (``tatl_mj.experiments.results.pairs``).

Each pair answers two questions, seed by seed on the seeds both finished (paired: a seed's
methods share its source policy, target samples and evaluation starts):

- **final**: the normalised score at the largest budget;
- **efficiency**: the area under the normalised curve over log counted real-target
  transitions (``statistics.efficiency_area``): one fixed range for every method of the
  experiment (the preset's smallest to largest budget), the random policy's score (0)
  before a method's first policy, scores floored at -1.

Each question's verdict comes from the paired sign statistic and its exact interval
(``statistics.sign_probability``): credited / worse / not credited. The efficiency question
is also answered on the paper's accounting (apprentice samples only, Algorithm 2's U_M
rollouts not counted), a secondary column. Within an experiment, each question's family is
its declared pairs; intervals are unadjusted and Holm's correction over the family is
reported beside them (``holm``). A mapping variant's pair of two methods without a source is
its parent's records: it belongs to the parent's family and is marked, not counted twice.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from tatl_mj.experiments.results import statistics as stats
from tatl_mj.experiments.results.pairs import (
    ABLATION,
    BEST_BASELINE,
    EFFICIENCY,
    FINAL,
    PLACEBO,
    QUESTIONS,
    declared_pairs,
    family_sizes,
    parents_pair,
)

VERDICT_RULE_VERSION = 2
"""Bumped whenever a change to this rule can move a verdict (written into summary.json).
1: P(X > Y) over all pairs of seeds on the area alone (unpaired), best baseline picked on the
reported seeds. 2: this module."""

SCORE_FLOOR = -1.0
"""Normalised scores below it count as it in the efficiency area: one blown-up fit (a score of
-10^6) cannot decide a seed; -1 is as far below random as the reference is above it."""
BEFORE_FIRST_POLICY = 0.0
"""What a method scores before its first policy: the random policy's normalised score. Every
data protocol here collects its first transitions with a random policy, and before a method
has returned a policy there is nothing of its own to deploy."""


@dataclasses.dataclass(frozen=True)
class Answer:
    """One question of one pair: the paired sign statistic, its p-value, the effect size."""

    probability: stats.Estimate
    signs: stats.PairedSigns
    p_value: float
    median_difference: stats.Estimate
    unpaired: stats.Estimate

    @property
    def verdict(self) -> str:
        return stats.verdict(self.probability)

    def as_dict(self) -> dict:
        return {
            "probability": self.probability.as_dict(),
            "seeds": self.signs.as_dict(),
            "p_value": None if np.isnan(self.p_value) else float(self.p_value),
            "median_difference": self.median_difference.as_dict(),
            "unpaired_probability": self.unpaired.as_dict(),
            "verdict": self.verdict,
        }


def answer(x: np.ndarray, y: np.ndarray) -> Answer:
    """The paired answer for per-seed statistics ``x`` (the method) and ``y`` (the other), seed by seed."""
    signs = stats.paired_signs(x, y)
    return Answer(
        probability=stats.sign_probability(signs),
        signs=signs,
        p_value=stats.sign_p_value(signs),
        median_difference=stats.median_difference(x, y),
        unpaired=stats.improvement_interval([(np.asarray(x), np.asarray(y))]),
    )


def judge(
    spec: Mapping[str, Any],
    per_seed: Mapping[str, Mapping[str, np.ndarray]],
    paper_efficiency: Mapping[str, np.ndarray] | None = None,
) -> list[dict]:
    """Every declared pair whose methods both have per-seed statistics, answered.

    ``per_seed[question][method]`` holds the method's statistic on the compared seeds (the
    same seeds, in the same order, for every method); ``paper_efficiency[method]`` the
    efficiency area on the paper's accounting. Holm's correction runs per question over
    the family the spec declares (``family_sizes``).
    """
    sizes = family_sizes(spec)
    out = []
    for pair in declared_pairs(spec):
        have = all(pair.method in per_seed[q] and pair.other in per_seed[q] for q in pair.questions)
        if not have:
            continue
        entry: dict[str, Any] = {
            "method": pair.method,
            "other": pair.other,
            "role": pair.role,
            "parents": parents_pair(spec, pair),
        }
        for question in pair.questions:
            entry[question] = answer(per_seed[question][pair.method], per_seed[question][pair.other]).as_dict()
        if EFFICIENCY in pair.questions and paper_efficiency is not None:
            entry["efficiency_paper"] = answer(paper_efficiency[pair.method], paper_efficiency[pair.other]).as_dict()
        out.append(entry)
    for question in QUESTIONS:
        asked = [e for e in out if question in e and not e["parents"]]
        p_values = [e[question]["p_value"] if e[question]["p_value"] is not None else np.nan for e in asked]
        for entry, rejected in zip(asked, stats.holm(p_values, max(sizes[question], len(asked)))):
            entry[question]["holm"] = bool(rejected) and entry[question]["verdict"] != stats.NOT_CREDITED
    return out


def choose_best_baseline(experiment: Mapping[str, Any], baselines: Sequence[str]) -> dict[str, str]:
    """Per question, the baseline with the highest IQM of that question's per-seed statistic in a
    summary experiment (``final_iqm`` and ``efficiency``): run on the tuning seeds, then frozen
    in the spec's ``best_baseline``. Ties go to the baseline listed first."""
    methods = experiment.get("methods") or {}
    fields = {FINAL: "final_iqm", EFFICIENCY: "efficiency"}
    chosen = {}
    for question, field in fields.items():
        scored = [(b, (methods[b].get(field) or {}).get("value")) for b in baselines if b in methods]
        scored = [(b, v) for b, v in scored if v is not None]
        if scored:
            chosen[question] = max(scored, key=lambda bv: bv[1])[0]  # max keeps the first of equals
    return chosen


__all__ = [
    "ABLATION",
    "BEST_BASELINE",
    "EFFICIENCY",
    "FINAL",
    "PLACEBO",
    "QUESTIONS",
    "SCORE_FLOOR",
    "VERDICT_RULE_VERSION",
    "Answer",
    "answer",
    "choose_best_baseline",
    "judge",
]
