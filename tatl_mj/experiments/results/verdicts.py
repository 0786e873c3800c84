"""The verdict rule, whole and in one place, under :data:`VERDICT_RULE_VERSION` (docs/protocol.md,
"Verdicts", declares it with its reasons).

- Pairs, declared by the spec from the roles its methods declare
  (``tatl_mj.experiments.results.pairs``): a transfer method against its source-free
  **ablation**, against itself on a **placebo** source, any method that is not a baseline
  against the frozen **best baseline** (``choose_best_baseline`` here, on the tuning seeds).
- Per seed (paired: a seed's methods share its source policy, target samples and evaluation
  starts), on normalised scores (``normalised``), two questions (``scored``): **final**, the
  score at the largest budget; **efficiency**, the area over log counted transitions
  (``efficiency_area``, ``transitions``: also on the paper's accounting, a secondary column).
- Each question's verdict: the paired sign statistic (``paired_signs``) with its exact interval
  (``sign_probability``, ``verdict``, ``words``), the median paired difference beside it
  (``median_difference``), Holm's correction over the declared family (``holm``,
  ``family_sizes``; a variant's pair that is its parent's records: ``parents_pair``).
- Without a reference return, one sentence per ablation pair (``ablation_verdict``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any, Protocol

import numpy as np
import scipy.special
import scipy.stats

from tatl_mj.experiments.results import statistics as stats
from tatl_mj.experiments.results.pairs import (
    ABLATION,
    BEST_BASELINE,
    EFFICIENCY,
    FINAL,
    PLACEBO,
    QUESTIONS,
    ablation_pairs,
    declared_pairs,
    family_sizes,
    parents_pair,
)
from tatl_mj.experiments.results.statistics import CONFIDENCE, Estimate

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
CREDITED, WORSE, NOT_CREDITED = "credited", "worse", "not credited"
TIE_TOLERANCE = 1e-9  # paired differences this small are ties (another summation order, not a difference)
COUNTED, PAPER = "counted", "paper"  # every real-target transition used; the apprentice's samples only
ACCOUNTINGS = (COUNTED, PAPER)


class Compared(Protocol):
    """What the no-reference sentence reads of one method (``comparison.MethodResult``)."""

    @property
    def final_returns(self) -> tuple[float, ...]: ...
    @property
    def samples_to_threshold(self) -> tuple[float, ...]: ...
    @property
    def median_samples(self) -> float: ...


class Comparison(Protocol):
    """What the no-reference sentence reads of an experiment's comparison (``comparison.Comparison``)."""

    @property
    def meaningful(self) -> bool: ...
    def result(self, method: str) -> Compared | None: ...


def normalised(returns: np.ndarray, random_return: np.ndarray | float, reference: float) -> np.ndarray:
    """``(R - R_random) / (R_reference - R_random)``; ValueError when the reference is not above random."""
    random_return = np.asarray(random_return, dtype=np.float64)
    span = reference - random_return
    if np.any(span <= 0):
        raise ValueError(f"the reference return {reference} must lie above the random policy's {random_return}")
    return (np.asarray(returns, dtype=np.float64) - random_return) / span


def transitions(
    target: Any, rollouts: Any, accounting: str = COUNTED, budgets: Sequence[float] | None = None
) -> np.ndarray:
    """[seed][budget] transitions on an ``accounting``: ``target`` every one counted, ``rollouts``
    Algorithm 2's among them (the paper's leaves them out). With ``budgets``, a point that counted
    none (a reference, learned without the target) stands at its budget, as a log axis and the
    first policy read it; the area takes the counts as they are (below its range: from its start)."""
    counts = np.asarray(target, dtype=np.float64)
    if accounting == PAPER:
        counts = counts - np.asarray(rollouts, dtype=np.float64)
    if budgets is None:
        return counts
    return np.where(counts > 0, counts, np.asarray(budgets, dtype=np.float64))


def efficiency_area(
    counts: np.ndarray,
    scores: np.ndarray,
    low: float,
    high: float,
    floor: float = SCORE_FLOOR,
    before: float = BEFORE_FIRST_POLICY,
) -> np.ndarray:
    """Per seed, the mean normalised score over log counted transitions in [low, high].

    Each seed's curve is a step function of the real-target transitions it counted:
    at x, the score (floored at ``floor``) of its last budget whose count is <= x,
    and ``before`` (0: the random policy's score) before its first. The same range
    serves every method, so a method that counts more transitions for a budget is
    credited later; points counted beyond ``high`` fall outside. Exact (no grid):
    the integral of the steps over log10 x, divided by log10(high / low).
    """
    if not (0 < low < high):
        raise ValueError(f"the area's range needs 0 < low < high, got [{low}, {high}]")
    counts = np.atleast_2d(np.asarray(counts, dtype=np.float64))
    scores = np.maximum(np.atleast_2d(np.asarray(scores, dtype=np.float64)), floor)
    if counts.shape != scores.shape:
        raise ValueError(f"counts {counts.shape} and scores {scores.shape} differ in shape")
    lo, hi = math.log10(low), math.log10(high)
    out = np.empty(len(scores))
    for i, (c, y) in enumerate(zip(counts, scores)):
        order = np.argsort(c, kind="stable")  # equal counts: the later budget holds from there
        edges = np.log10(np.clip(c[order], low, high))
        values = y[order]
        # Steps: [lo, e0) -> before, [e_k, e_{k+1}) -> values[k], [e_last, hi] -> values[-1].
        bounds = np.concatenate([[lo], edges, [hi]])
        levels = np.concatenate([[before], values])
        out[i] = float(np.sum(np.diff(bounds) * levels)) / (hi - lo)
    return out


@dataclasses.dataclass(frozen=True, eq=False)
class Scored:
    """One method's per-seed statistics on the compared seeds, what its verdicts are judged on."""

    normalised: np.ndarray  # [seed][budget]
    efficiency: dict[str, np.ndarray]  # per accounting, per seed: the efficiency area
    first_policy: dict[str, float]  # per accounting, the median over seeds of what it counted first

    @property
    def final(self) -> np.ndarray:
        """Per seed, the normalised score at the largest budget (the final question)."""
        return self.normalised[:, -1]


def scored(
    returns: Any, random_returns: np.ndarray, reference: float, target: Any, rollouts: Any, budgets: Sequence[float]
) -> Scored:
    """A method's :class:`Scored` from its [seed][budget] returns and transitions (the compared
    seeds, in order), the random policy's return per seed and the experiment's reference return,
    the area over the experiment's smallest to largest budget."""
    scores = normalised(returns, np.asarray(random_returns)[:, None], reference)
    low, high = float(budgets[0]), float(budgets[-1])
    return Scored(
        normalised=scores,
        efficiency={a: efficiency_area(transitions(target, rollouts, a), scores, low, high) for a in ACCOUNTINGS},
        first_policy={a: float(np.median(transitions(target, rollouts, a, budgets)[:, 0])) for a in ACCOUNTINGS},
    )


def verdict(estimate: Estimate) -> str:
    """``credited`` when the interval lies above 0.5, ``worse`` below, else ``not credited``."""
    if math.isfinite(estimate.low) and estimate.low > 0.5:
        return CREDITED
    if math.isfinite(estimate.high) and estimate.high < 0.5:
        return WORSE
    return NOT_CREDITED


def words(role: str, marked: bool = False) -> dict[str, str]:
    """Each verdict's word for a pair of ``role``: against the best baseline better / worse / no clear
    difference, else credited / worse / not credited; ``marked``: bold (markdown) but "not credited"."""
    plain = (
        {CREDITED: "better", WORSE: "worse", NOT_CREDITED: "no clear difference"}
        if role == BEST_BASELINE
        else {CREDITED: "credited", WORSE: "worse", NOT_CREDITED: "not credited"}
    )
    return {v: f"**{w}**" if marked and v != NOT_CREDITED else w for v, w in plain.items()}


@dataclasses.dataclass(frozen=True)
class PairedSigns:
    """How many seeds favour each side of a paired comparison (``|d| <= TIE_TOLERANCE``: tied)."""

    better: int
    tied: int
    worse: int

    @property
    def n(self) -> int:
        return self.better + self.tied + self.worse

    @property
    def successes(self) -> float:
        """Seeds where the method is better, ties counting one half."""
        return self.better + 0.5 * self.tied

    def as_dict(self) -> dict:
        return {"better": self.better, "tied": self.tied, "worse": self.worse}


def paired_signs(x: np.ndarray, y: np.ndarray, tolerance: float = TIE_TOLERANCE) -> PairedSigns:
    """Seed by seed (x[i] against y[i], the same seed), how many favour x, tie and favour y.

    NaN differences (a statistic that could not be computed) count as ties: no side
    is credited with a seed it did not win.
    """
    d = _paired_differences(x, y)
    with np.errstate(invalid="ignore"):
        better, worse = int(np.sum(d > tolerance)), int(np.sum(d < -tolerance))
    return PairedSigns(better, len(d) - better - worse, worse)


def _paired_differences(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    x, y = np.asarray(x, dtype=np.float64).ravel(), np.asarray(y, dtype=np.float64).ravel()
    if x.shape != y.shape:
        raise ValueError(f"paired statistics need one value per seed on both sides, got {len(x)} and {len(y)}")
    return x - y


def sign_probability(signs: PairedSigns, confidence: float = CONFIDENCE) -> Estimate:
    """P(better on a seed), ties half, with Clopper-Pearson's exact interval.

    With ``k = better + tied / 2`` of ``n``: the interval is ``[B(a/2; k, n-k+1),
    B(1-a/2; k+1, n-k)]`` (B the beta distribution's quantile, a = 1 - confidence),
    its low end 0 at k = 0 and its high end 1 at k = n. No seed: NaN.
    """
    n, k = signs.n, signs.successes
    if n == 0:
        return Estimate(math.nan, math.nan, math.nan)
    alpha = 1.0 - confidence
    low = 0.0 if k <= 0 else float(scipy.stats.beta.ppf(alpha / 2, k, n - k + 1))
    high = 1.0 if k >= n else float(scipy.stats.beta.ppf(1 - alpha / 2, k + 1, n - k))
    return Estimate(k / n, low, high)


def seeds_to_credit(n: int, confidence: float = CONFIDENCE) -> int | None:
    """The fewest of ``n`` paired seeds that must favour a method (the rest against it, no tie)
    for :func:`sign_probability`'s interval to lie above 0.5, so that :func:`verdict` can credit
    it (by symmetry, as many against it to find it worse); None where even all ``n`` cannot:
    at 95%, 5 of 5 gives [0.48, 1.00], 6 of 6 [0.54, 1.00], and 9 of 10 [0.55, 1.00]."""
    for k in range(n + 1):
        if verdict(sign_probability(PairedSigns(k, 0, n - k), confidence)) == CREDITED:
            return k
    return None


def sign_p_value(signs: PairedSigns) -> float:
    """The two-sided p-value of the sign test matching :func:`sign_probability`'s interval.

    One-sided, P(Bin(n, 1/2) >= k) = I_1/2(k, n-k+1) (the regularised incomplete
    beta, which allows a half count k); the interval lies above 0.5 exactly when
    that is below (1 - confidence) / 2. Two-sided: twice the smaller tail, at most 1.
    """
    n, k = signs.n, signs.successes
    if n == 0:
        return math.nan
    greater = 1.0 if k <= 0 else float(scipy.special.betainc(k, n - k + 1, 0.5))
    less = 1.0 if k >= n else float(scipy.special.betainc(n - k, k + 1, 0.5))
    return min(1.0, 2.0 * min(greater, less))


def median_difference(x: np.ndarray, y: np.ndarray, confidence: float = CONFIDENCE) -> Estimate:
    """The median paired difference ``x - y`` with a distribution-free interval.

    The interval is ``[d_(j), d_(n+1-j)]`` of the sorted differences, j the largest
    index with P(Bin(n, 1/2) <= j - 1) <= (1 - confidence) / 2, so it covers the
    median with at least ``confidence`` whatever the differences' distribution (at
    n = 10: d_(2) to d_(9), 97.9%). Fewer than 6 seeds give no 95% interval (NaN).
    """
    d = np.sort(_paired_differences(x, y))
    d = d[np.isfinite(d)]
    n = len(d)
    if n == 0:
        return Estimate(math.nan, math.nan, math.nan)
    point = float(np.median(d))
    j = int(scipy.stats.binom.ppf((1.0 - confidence) / 2, n, 0.5))
    if scipy.stats.binom.cdf(j, n, 0.5) > (1.0 - confidence) / 2:
        j -= 1  # ppf gives the first index whose tail exceeds the level: one below it is the last within
    if j < 0:
        return Estimate(point, math.nan, math.nan)
    return Estimate(point, float(d[j]), float(d[n - 1 - j]))


def holm(p_values: Sequence[float], family_size: int, level: float = 1.0 - CONFIDENCE) -> list[bool]:
    """Holm's step-down rejections at familywise ``level`` for ``p_values``, in their order.

    ``family_size`` (m) is the number of comparisons the family declares, which may
    exceed the p-values given (a declared pair a run did not compute counts as not
    rejected): the i-th smallest p-value (from 0) is rejected when it and every
    smaller one lie at or below ``level / (m - i)``. NaN is never rejected.
    """
    if family_size < len(p_values):
        raise ValueError(f"a family of {family_size} comparisons cannot hold {len(p_values)} p-values")
    order = sorted(range(len(p_values)), key=lambda i: (math.isnan(p_values[i]), p_values[i]))
    rejected = [False] * len(p_values)
    for rank, i in enumerate(order):
        p = p_values[i]
        if math.isnan(p) or p > level / (family_size - rank):
            break
        rejected[i] = True
    return rejected


@dataclasses.dataclass(frozen=True)
class Answer:
    """One question of one pair: the paired sign statistic, its p-value, the effect size."""

    probability: Estimate
    signs: PairedSigns
    p_value: float
    median_difference: Estimate
    unpaired: Estimate

    @property
    def verdict(self) -> str:
        return verdict(self.probability)

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
    signs = paired_signs(x, y)
    return Answer(
        probability=sign_probability(signs),
        signs=signs,
        p_value=sign_p_value(signs),
        median_difference=median_difference(x, y),
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
        for entry, rejected in zip(asked, holm(p_values, max(sizes[question], len(asked)))):
            entry[question]["holm"] = bool(rejected) and entry[question]["verdict"] != NOT_CREDITED
    return out


def _side(mine: np.ndarray, theirs: np.ndarray, mine_centre: float, theirs_centre: float) -> tuple[int, int, int]:
    """(+1 better / -1 worse / 0 neither, seeds better, seeds worse) where larger is better."""
    better, worse = int(np.sum(mine > theirs)), int(np.sum(mine < theirs))
    if mine_centre > theirs_centre and better > len(mine) / 2:
        return 1, better, worse
    if mine_centre < theirs_centre and worse > len(mine) / 2:
        return -1, better, worse
    return 0, better, worse


def ablation_verdict(comparison: Comparison, method: str, ablation: str) -> str | None:
    """One plain sentence: does ``method`` beat its source-free ``ablation``?

    Seed by seed on the compared seeds, on final return (mean) and, where the
    threshold is meaningful, on target transitions to threshold (median; fewer is
    better): a side counts when the aggregate and more than half the seeds agree.
    It beats the ablation when one side is better and neither is worse.
    """
    mine, theirs = comparison.result(method), comparison.result(ablation)
    if mine is None or theirs is None:
        return None
    a, b = np.asarray(mine.final_returns), np.asarray(theirs.final_returns)
    n = len(a)
    ret, higher, lower = _side(a, b, a.mean(), b.mean())
    parts = [f"mean final return {a.mean():.4g} vs {b.mean():.4g} (higher on {higher}, lower on {lower} of {n} seeds)"]
    sides = [ret]
    if comparison.meaningful:
        sa, sb = np.asarray(mine.samples_to_threshold), np.asarray(theirs.samples_to_threshold)
        samp, fewer, more = _side(-sa, -sb, -mine.median_samples, -theirs.median_samples)
        sides.append(samp)
        parts.append(
            f"median target transitions to threshold {_samples_text(mine.median_samples)} vs "
            f"{_samples_text(theirs.median_samples)} (fewer on {fewer}, more on {more} of {n} seeds)"
        )
    if max(sides) == 1 and min(sides) >= 0:
        verdict = "**beats** its source-free ablation: this gain is credited to transfer"
    elif min(sides) == -1 and max(sides) <= 0:
        verdict = "**does not beat** its source-free ablation: it is **worse**, the source hurts here"
    elif min(sides) == -1:
        verdict = "**does not clearly beat** its source-free ablation: better on one measure, worse on the other"
    else:
        verdict = "**does not beat** its source-free ablation (no clear difference): no gain is credited to transfer"
    return f"`{method}` vs `{ablation}`: {'; '.join(parts)}: `{method}` {verdict}."


def ablation_sentences(spec_methods: Mapping[str, Any], comparison: Comparison) -> list[str]:
    """:func:`ablation_verdict` for every ablation pair a spec's methods declare (the judgement
    where there is no reference return to normalise by)."""
    pairs = ablation_pairs(spec_methods)
    return [v for v in (ablation_verdict(comparison, m, a) for m, a in pairs) if v]


def _samples_text(value: float) -> str:
    return "never" if not math.isfinite(value) else f"{value:,.0f}"


def choose_best_baseline(methods: Mapping[str, Any], baselines: Sequence[str]) -> dict[str, str]:
    """Per question, the baseline with the highest IQM of that question's per-seed statistic among a
    summary experiment's ``methods`` (``summary_data.MethodSummary``: ``final_iqm``, ``efficiency``):
    run on the tuning seeds, then frozen in the spec's ``best_baseline``. Ties go to the one listed first."""
    fields = {FINAL: "final_iqm", EFFICIENCY: "efficiency"}
    chosen = {}
    for question, field in fields.items():
        estimates = [(b, getattr(methods[b], field)) for b in baselines if b in methods]
        scored = [(b, None if e is None else e.value) for b, e in estimates]
        scored = [(b, v) for b, v in scored if v is not None]
        if scored:
            chosen[question] = max(scored, key=lambda bv: bv[1])[0]  # max keeps the first of equals
    return chosen


__all__ = [
    "ABLATION",
    "ACCOUNTINGS",
    "BEFORE_FIRST_POLICY",
    "BEST_BASELINE",
    "COUNTED",
    "CREDITED",
    "EFFICIENCY",
    "FINAL",
    "NOT_CREDITED",
    "PAPER",
    "PLACEBO",
    "QUESTIONS",
    "SCORE_FLOOR",
    "TIE_TOLERANCE",
    "VERDICT_RULE_VERSION",
    "WORSE",
    "Answer",
    "PairedSigns",
    "Scored",
    "ablation_sentences",
    "ablation_verdict",
    "answer",
    "choose_best_baseline",
    "efficiency_area",
    "holm",
    "judge",
    "median_difference",
    "normalised",
    "paired_signs",
    "scored",
    "seeds_to_credit",
    "sign_p_value",
    "sign_probability",
    "transitions",
    "verdict",
    "words",
]
