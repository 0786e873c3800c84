"""The comparison of the methods of one experiment: the seeds they share, the threshold and each
method's transitions to it (:func:`compare_methods`, :func:`comparison_of`; not ``tatl compare``,
which runs a user's methods against a reference set).

Definitions (one place; the table, the figures and summary.json all use them):

- Seeds compared: only the seeds every method with any finished record shares
  (and whose source unit finished). A method that finished extra seeds has them
  listed, not averaged in; when the seed sets differ the table says so.
- Threshold: ``R_random + 0.9 (R_reference - R_random)``, a normalised score of
  0.9, where ``R_reference`` is the experiment's fixed reference return (its
  preset's ``reference_return``) and ``R_random`` the uniformly random policy's
  return under the same evaluation protocol (mean over the compared seeds). A
  spec that declares no reference falls back to ``R_random + 0.95 (R_best -
  R_random)``, ``R_best`` the best method's mean final return (relative to the
  methods listed, so the table says so).
- No meaningful threshold: a threshold at or below ``R_random`` (no method beat
  the random policy on average) says nothing about learning speed; samples to
  threshold are then not reported and the experiment is judged on final returns.
- Samples to threshold of one seed: the real-target transitions it counted
  (``target_transitions``: its samples, Algorithm 2's rollouts, its own data) at
  the smallest budget from which its return stays at or above the threshold at
  every larger budget (a method that crosses and falls back has not reached it);
  ``math.inf`` if it never does (``null`` in summary.json, which has no infinity).
  The same on the paper's accounting (its apprentice samples, Algorithm 2's rollouts not
  counted) is ``samples_to_threshold_paper``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from tatl_mj.experiments.results import verdicts
from tatl_mj.experiments.results.summary_data import Experiment, MethodSummary

THRESHOLD_FRACTION = 0.95  # of the gap to the best method: only without a declared reference
REFERENCE_THRESHOLD = 0.9  # normalised score: the threshold with a declared reference return


def samples_to_threshold(
    samples: Sequence[float],
    returns: Sequence[float],
    threshold: float,
    counts: Sequence[float] | None = None,
) -> float:
    """The smallest budget from which ``returns`` stay >= ``threshold`` for every larger budget.

    ``samples`` are the budgets in increasing order and ``returns`` the return at
    each; ``math.inf`` if the last return is below the threshold. With ``counts``
    (the target transitions counted at each budget) the answer is that budget's count.
    """
    if len(samples) != len(returns) or (counts is not None and len(counts) != len(samples)):
        raise ValueError(f"samples, returns and counts differ in length: {len(samples)} != {len(returns)}")
    if any(b <= a for a, b in zip(samples[:-1], samples[1:])):
        raise ValueError(f"samples must be strictly increasing budgets, got {list(samples)}")
    counted = samples if counts is None else counts
    reached = math.inf
    for count, value in zip(reversed(counted), reversed(returns)):
        if not value >= threshold:  # NaN counts as below
            break
        reached = count
    return reached


def threshold_for(
    final_means: dict[str, float], random_return: float, fraction: float = THRESHOLD_FRACTION
) -> tuple[float, str, bool]:
    """``(threshold, best_method, meaningful)`` from each method's mean final return.

    ``meaningful`` is False when the threshold is at or below ``random_return``.
    """
    if not final_means:
        raise ValueError("final_means is empty: no method to take the best of")
    best = max(final_means, key=lambda m: final_means[m])
    threshold = random_return + fraction * (final_means[best] - random_return)
    return threshold, best, bool(threshold > random_return)


@dataclass(frozen=True)
class MethodResult:
    """One method over the compared seeds (``seeds``, in that order)."""

    method: str
    seeds: tuple[int, ...]
    final_returns: tuple[float, ...]
    samples_to_threshold: tuple[float, ...]  # math.inf: never; empty when no meaningful threshold
    extra_seeds: tuple[int, ...]  # finished but not shared by every method: not compared
    largest_budget: int
    # The same on the paper's accounting (its samples, Algorithm 2's rollouts not counted).
    samples_to_threshold_paper: tuple[float, ...] = ()

    @property
    def reached(self) -> int:
        return sum(math.isfinite(v) for v in self.samples_to_threshold)

    @property
    def median_samples(self) -> float:
        """Median over seeds, a seed that never reached the threshold counting as infinite."""
        return float(np.median(self.samples_to_threshold)) if self.samples_to_threshold else math.nan

    @property
    def median_samples_paper(self) -> float:
        """:attr:`median_samples` on the paper's accounting."""
        paper = self.samples_to_threshold_paper
        return float(np.median(paper)) if paper else math.nan


@dataclass(frozen=True)
class Comparison:
    """Every method of one experiment on the seeds they share; see the module docstring."""

    seeds: tuple[int, ...]
    methods: tuple[MethodResult, ...]
    missing: tuple[str, ...]  # methods asked for with no finished seed
    random_return: float | None
    threshold: float | None
    best_method: str | None
    meaningful: bool

    @property
    def seed_sets_differ(self) -> bool:
        return bool(self.missing) or any(r.extra_seeds for r in self.methods)

    def result(self, method: str) -> MethodResult | None:
        return next((r for r in self.methods if r.method == method), None)


def compare_methods(
    methods: Mapping[str, MethodSummary],
    random_by_seed: Mapping[int, float] | None,
    reference: float | None,
    asked: Sequence[str] | None = None,
    fraction: float = THRESHOLD_FRACTION,
) -> Comparison:
    """Compares the ``methods`` of one experiment over their shared seeds.

    ``random_by_seed`` is the random policy's return per source seed (None: a summary older
    than them), ``reference`` the experiment's reference return. ``asked`` are the names asked
    for, in display order (default: those with records, in the summary's order).
    """
    asked = list(methods) if asked is None else list(asked)
    present = [m for m in asked if m in methods and methods[m].seeds]
    missing = tuple(m for m in asked if m not in present)
    shared = sorted(set.intersection(*(set(methods[m].seeds) for m in present))) if present else []
    if random_by_seed is not None:
        shared = [s for s in shared if s in random_by_seed]
    rows = {m: methods[m].rows(shared) for m in present}
    random_return = None
    if random_by_seed:
        # Without shared seeds there is no threshold; the value is still worth showing.
        random_return = float(np.mean([random_by_seed[s] for s in (shared or random_by_seed)]))
    threshold, best, meaningful = None, None, False
    if shared and random_return is not None:
        finals = {m: float(np.mean([methods[m].final_return[i] for i in rows[m]])) for m in present}
        threshold, best, meaningful = threshold_for(finals, random_return, fraction)
        if reference is not None:  # fixed: no method added or removed can move it
            threshold = random_return + REFERENCE_THRESHOLD * (reference - random_return)
            meaningful = bool(reference > random_return)
    out = []
    for m in present:
        data = methods[m]
        budgets = list(data.curve.samples)
        reached: tuple[float, ...] = ()
        reached_paper: tuple[float, ...] = ()
        if meaningful:
            reached, reached_paper = (
                tuple(
                    samples_to_threshold(budgets, data.curve.mean_return[i], threshold, counts[i])  # type: ignore[arg-type]
                    for i in rows[m]
                )
                for counts in (data.curve.transitions(a, placed=False) for a in verdicts.ACCOUNTINGS)
            )
        out.append(
            MethodResult(
                method=m,
                seeds=tuple(shared),
                final_returns=tuple(float(data.final_return[i]) for i in rows[m]),
                samples_to_threshold=reached,
                extra_seeds=tuple(s for s in data.seeds if s not in shared),
                largest_budget=int(max(budgets)),
                samples_to_threshold_paper=reached_paper,
            )
        )
    return Comparison(
        seeds=tuple(shared),
        methods=tuple(out),
        missing=missing,
        random_return=random_return,
        threshold=threshold,
        best_method=best,
        meaningful=meaningful,
    )


def comparison_of(
    experiment: Experiment, methods: Sequence[str] | None = None, fraction: float = THRESHOLD_FRACTION
) -> Comparison:
    """:func:`compare_methods` of a summary's experiment."""
    random_by_seed, reference = experiment.random_by_seed, experiment.reference_return
    return compare_methods(experiment.methods, random_by_seed, reference, methods, fraction)


__all__ = [
    "REFERENCE_THRESHOLD",
    "THRESHOLD_FRACTION",
    "Comparison",
    "MethodResult",
    "compare_methods",
    "comparison_of",
    "samples_to_threshold",
    "threshold_for",
]
