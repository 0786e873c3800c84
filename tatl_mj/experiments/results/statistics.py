"""Interval estimates for the verdicts: normalised scores, IQM, probability of improvement.

The definitions follow Agarwal et al. (NeurIPS 2021, "Deep RL at the edge of the
statistical precipice", the ``rliable`` package), computed with
``scipy.stats.bootstrap``:

- normalised score of a return R: ``(R - R_random) / (R_reference - R_random)``, with
  the experiment's fixed reference return (declared in its spec, never computed
  from the methods compared) and the random policy's return of the same seed;
- IQM: the interquartile mean, the mean of the middle 50% of the scores
  (``scipy.stats.trim_mean(x, 0.25)``), over runs (seeds), or over every run of
  every experiment for an aggregate;
- probability of improvement ``P(X > Y)``: the chance that a run of method X
  scores above a run of method Y of the same experiment, ties counting one half
  (the Mann-Whitney statistic over n m); averaged over experiments for an aggregate;
- 95% intervals from a stratified percentile bootstrap: the runs of each
  experiment (and of each method) are resampled with replacement on their own.

Verdicts (docs/protocol.md, "Verdicts") are paired: the seeds of one experiment
share the source policy, target samples and evaluation starts, so two methods are
compared seed by seed:

- per seed, the paired difference ``d = x - y`` of a per-seed statistic (the
  normalised final score, or the efficiency area);
- the verdict statistic ``P = (better + tied / 2) / n``, the probability that the
  method is better on a seed, ties counted half (``|d| <= TIE_TOLERANCE``);
- its interval: Clopper-Pearson's exact 95% interval on the sign, with
  ``better + tied / 2`` successes of ``n`` (the beta-quantile form, so a half
  count is allowed). It is defined and non-degenerate at 10 of 10 seeds
  agreeing, where a bootstrap collapses to a point or returns NaN;
- **credited** when the interval lies above 0.5, **worse** below, **not credited**
  otherwise: the two-sided sign test at 5%, whose p-value (``sign_p_value``)
  feeds Holm's correction within a family (``holm``);
- the effect size beside it: the median paired difference with its
  distribution-free interval from order statistics (``median_difference``).

The unpaired P(X > Y) over all seed pairs (``improvement_interval``) stays as a
secondary number.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
import scipy.special
import scipy.stats

CONFIDENCE = 0.95
RESAMPLES = 2000
BOOTSTRAP_SEED = 0  # intervals are reproducible: the same records give the same numbers

CREDITED, WORSE, NOT_CREDITED = "credited", "worse", "not credited"
# Paired differences this small are ties: two methods whose per-seed statistics differ
# only in the last bits of a sum (another summation order) are not told apart.
TIE_TOLERANCE = 1e-9


@dataclasses.dataclass(frozen=True)
class Estimate:
    """A point estimate with its interval (NaN bounds where no interval can be had)."""

    value: float
    low: float
    high: float

    def as_dict(self) -> dict:
        return {"value": _json(self.value), "low": _json(self.low), "high": _json(self.high)}

    def text(self, fmt: str = ".2f") -> str:
        if not math.isfinite(self.low):
            return f"{self.value:{fmt}} (no interval)"
        return f"{self.value:{fmt}} [{self.low:{fmt}}, {self.high:{fmt}}]"


def _json(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def normalised(returns: np.ndarray, random_return: np.ndarray | float, reference: float) -> np.ndarray:
    """``(R - R_random) / (R_reference - R_random)``; ValueError when the reference is not above random."""
    random_return = np.asarray(random_return, dtype=np.float64)
    span = reference - random_return
    if np.any(span <= 0):
        raise ValueError(f"the reference return {reference} must lie above the random policy's {random_return}")
    return (np.asarray(returns, dtype=np.float64) - random_return) / span


def iqm(scores: np.ndarray, axis: int | None = None) -> np.ndarray | float:
    """The interquartile mean: the mean of the middle 50% (25% trimmed at each end)."""
    return scipy.stats.trim_mean(np.asarray(scores, dtype=np.float64), 0.25, axis=axis)


def _bootstrap(samples: Sequence[np.ndarray], statistic, point: float) -> Estimate:  # type: ignore[no-untyped-def]
    samples = [np.asarray(s, dtype=np.float64) for s in samples]
    if any(len(s) < 2 for s in samples) or not math.isfinite(point):
        return Estimate(point, math.nan, math.nan)
    if all(np.all(s == s[0]) for s in samples):  # nothing varies: the interval is the point
        return Estimate(point, point, point)
    result = scipy.stats.bootstrap(
        samples,
        statistic,
        n_resamples=RESAMPLES,
        vectorized=True,
        paired=False,
        axis=-1,
        confidence_level=CONFIDENCE,
        method="percentile",
        rng=np.random.default_rng(BOOTSTRAP_SEED),
    )
    return Estimate(point, float(result.confidence_interval.low), float(result.confidence_interval.high))


def iqm_interval(strata: Sequence[np.ndarray]) -> Estimate:
    """IQM over every score of ``strata`` (one array of per-seed scores per experiment),
    with a stratified-bootstrap interval."""

    def statistic(*parts: np.ndarray, axis: int = -1) -> np.ndarray:
        return iqm(np.concatenate(parts, axis=axis), axis=axis)

    point = float(iqm(np.concatenate([np.asarray(s, dtype=np.float64) for s in strata])))
    return _bootstrap(strata, statistic, point)


def _improvement(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """P(X > Y) + P(X = Y) / 2 over the last axis of each (batched)."""
    greater = (x[..., :, None] > y[..., None, :]).mean(axis=(-2, -1))
    equal = (x[..., :, None] == y[..., None, :]).mean(axis=(-2, -1))
    return greater + 0.5 * equal


def improvement_interval(pairs: Sequence[tuple[np.ndarray, np.ndarray]]) -> Estimate:
    """P(X > Y) averaged over experiments (one ``(x_scores, y_scores)`` pair each), with a
    stratified-bootstrap interval; X's and Y's seeds are resampled independently."""
    flat = [np.asarray(a, dtype=np.float64) for pair in pairs for a in pair]

    def statistic(*parts: np.ndarray, axis: int = -1) -> np.ndarray:
        return np.mean([_improvement(parts[i], parts[i + 1]) for i in range(0, len(parts), 2)], axis=0)

    point = float(np.mean([_improvement(flat[i], flat[i + 1]) for i in range(0, len(flat), 2)]))
    return _bootstrap(flat, statistic, point)


def verdict(estimate: Estimate) -> str:
    """``credited`` when the interval lies above 0.5, ``worse`` below, else ``not credited``."""
    if math.isfinite(estimate.low) and estimate.low > 0.5:
        return CREDITED
    if math.isfinite(estimate.high) and estimate.high < 0.5:
        return WORSE
    return NOT_CREDITED


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


def efficiency_area(
    counts: np.ndarray,
    scores: np.ndarray,
    low: float,
    high: float,
    floor: float = -1.0,
    before: float = 0.0,
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


def area_under_curve(budgets: Sequence[float], scores: np.ndarray) -> np.ndarray:
    """Per seed, the mean normalised score over log budget: the trapezoid area under the
    curve over log10(budget), divided by the log range (a curve at 1 everywhere scores 1)."""
    x = np.log10(np.asarray(budgets, dtype=np.float64))
    y = np.asarray(scores, dtype=np.float64)
    if len(x) < 2:
        return y[..., 0]
    return np.trapezoid(y, x, axis=-1) / (x[-1] - x[0])


def survival(lengths: Sequence[float], cap: float) -> tuple[np.ndarray, np.ndarray]:
    """Kaplan-Meier survival of episode lengths censored at ``cap`` (an episode that
    reaches the cap did not end): the distinct end times and S(t) just after each."""
    lengths = np.asarray(lengths, dtype=np.float64)
    ended, capped = lengths[lengths < cap], lengths[lengths >= cap]
    if len(ended) == 0:
        return np.array([]), np.array([])
    result = scipy.stats.ecdf(scipy.stats.CensoredData(uncensored=ended, right=capped))
    times, probabilities = np.asarray(result.sf.quantiles), np.asarray(result.sf.probabilities)
    ends = times < cap  # the censoring time is no end
    return times[ends], probabilities[ends]


def performance_profile(scores: np.ndarray, taus: np.ndarray) -> np.ndarray:
    """The fraction of runs whose normalised score exceeds each tau."""
    s = np.asarray(scores, dtype=np.float64).ravel()
    return (s[None, :] > np.asarray(taus, dtype=np.float64)[:, None]).mean(axis=1)


__all__ = [
    "CONFIDENCE",
    "CREDITED",
    "Estimate",
    "NOT_CREDITED",
    "PairedSigns",
    "TIE_TOLERANCE",
    "WORSE",
    "area_under_curve",
    "efficiency_area",
    "holm",
    "improvement_interval",
    "median_difference",
    "paired_signs",
    "sign_p_value",
    "sign_probability",
    "iqm",
    "iqm_interval",
    "normalised",
    "performance_profile",
    "seeds_to_credit",
    "survival",
    "verdict",
]
