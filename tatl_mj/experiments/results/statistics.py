"""Interval estimates beside the verdicts: IQM, probability of improvement, survival, profiles.

The definitions follow Agarwal et al. (NeurIPS 2021, "Deep RL at the edge of the
statistical precipice", the ``rliable`` package), computed with
``scipy.stats.bootstrap``:

- IQM: the interquartile mean, the mean of the middle 50% of the scores
  (``scipy.stats.trim_mean(x, 0.25)``), over runs (seeds), or over every run of
  every experiment for an aggregate;
- probability of improvement ``P(X > Y)``: the chance that a run of method X
  scores above a run of method Y of the same experiment, ties counting one half
  (the Mann-Whitney statistic over n m); averaged over experiments for an aggregate;
  a secondary number beside each verdict (``unpaired_probability``);
- 95% intervals from a stratified percentile bootstrap: the runs of each
  experiment (and of each method) are resampled with replacement on their own.

The verdict rule itself (normalised scores, the efficiency area, the paired sign
statistic, Holm's correction, the verdict words) is
:mod:`tatl_mj.experiments.results.verdicts`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
import scipy.stats

CONFIDENCE = 0.95
RESAMPLES = 2000
BOOTSTRAP_SEED = 0  # intervals are reproducible: the same records give the same numbers


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
    "Estimate",
    "area_under_curve",
    "improvement_interval",
    "iqm",
    "iqm_interval",
    "performance_profile",
    "survival",
]
