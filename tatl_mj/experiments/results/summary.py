"""Aggregates finished records into DIR/summary.json, and compares methods fairly.

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
- Interval estimates (``tatl_mj.experiments.results.statistics``), with a reference:
  per method and budget the IQM of the normalised score with its 95%
  stratified-bootstrap interval; the efficiency area under the normalised
  learning curve over log counted target transitions (``efficiency``), and on
  the paper's accounting (``efficiency_paper``); and the verdicts of the pairs
  the spec declares, two questions each (``tatl_mj.experiments.results.verdicts``).
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

:func:`compare` applies them to one experiment of a summary; the results table
and panel (b) of the figures are both drawn from its answer.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from tatl_mj.experiments.results import pairs, verdicts
from tatl_mj.experiments.results import statistics as stats
from tatl_mj.experiments.results.records import SCHEMA_VERSION, UNKNOWN_KERNELS, RunDirectory, read_record

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
    def final_mean(self) -> float:
        return float(np.mean(self.final_returns))

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


def compare(experiment: dict, methods: Sequence[str] | None = None, fraction: float = THRESHOLD_FRACTION) -> Comparison:
    """Compares the methods of one summary experiment over their shared seeds.

    ``experiment`` is ``summary["experiments"][name]``: it needs ``methods``
    (per method ``seeds``, ``final_return``, ``curve.samples`` and
    ``curve.mean_return``) and the random policy's return per seed
    (``random_returns``, aligned with ``source_seeds``). ``methods`` are the names asked for, in display order
    (default: those with records, in the summary's order).
    """
    data = experiment["methods"]
    asked = list(data) if methods is None else list(methods)
    present = [m for m in asked if data.get(m, {}).get("seeds")]
    missing = tuple(m for m in asked if m not in present)
    random_by_seed = _random_by_seed(experiment)
    shared = sorted(set.intersection(*(set(data[m]["seeds"]) for m in present))) if present else []
    if random_by_seed is not None:
        shared = [s for s in shared if s in random_by_seed]

    results = []
    for m in present:
        index = {seed: i for i, seed in enumerate(data[m]["seeds"])}
        rows = [index[s] for s in shared]
        results.append((m, rows, index))
    random_return = None
    if random_by_seed:
        # Without shared seeds there is no threshold; the value is still worth showing.
        random_return = float(np.mean([random_by_seed[s] for s in (shared or random_by_seed)]))
    threshold, best, meaningful = None, None, False
    reference = experiment.get("reference_return")
    if shared and random_return is not None:
        finals = {m: float(np.mean([data[m]["final_return"][i] for i in rows])) for m, rows, _ in results}
        threshold, best, meaningful = threshold_for(finals, random_return, fraction)
        if reference is not None:  # fixed: no method added or removed can move it
            threshold = random_return + REFERENCE_THRESHOLD * (reference - random_return)
            meaningful = bool(reference > random_return)

    out = []
    for m, rows, _ in results:
        curve = data[m]["curve"]
        budgets = list(curve["samples"])
        counts = curve.get("target_transitions")
        paper = _paper(curve) if counts and "rollout_transitions" in curve else counts
        reached: tuple[float, ...] = ()
        reached_paper: tuple[float, ...] = ()
        if meaningful:
            reached, reached_paper = (
                tuple(
                    samples_to_threshold(budgets, curve["mean_return"][i], threshold, way[i] if way else None)
                    for i in rows
                )
                for way in (counts, paper)
            )
        out.append(
            MethodResult(
                method=m,
                seeds=tuple(shared),
                final_returns=tuple(float(data[m]["final_return"][i]) for i in rows),
                samples_to_threshold=reached,
                extra_seeds=tuple(s for s in data[m]["seeds"] if s not in shared),
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


def ablation_sentences(experiment: dict, comparison: Comparison) -> list[str]:
    """:func:`ablation_verdict` for every ablation pair the experiment's spec declares (the
    judgement where there is no reference return to normalise by)."""
    declared = pairs.ablation_pairs((experiment.get("spec") or {}).get("methods") or {})
    return [v for v in (ablation_verdict(comparison, m, a) for m, a in declared) if v]


def _samples_text(value: float) -> str:
    return "never" if not math.isfinite(value) else f"{value:,.0f}"


def _random_by_seed(experiment: dict) -> dict[int, float] | None:
    if "random_returns" not in experiment:
        return None
    return dict(zip(experiment["source_seeds"], experiment["random_returns"]))


def _experiment(
    run_dir: RunDirectory, name: str, seeds: list[int], methods: list[str], reference: float | None = None
) -> dict:
    sources, records = _read_records(run_dir, name, seeds, methods)
    out_methods = {m: _method_entry(recs) for m, recs in records.items() if recs}
    source_seeds = sorted(sources)
    # Per method, the seeds on which Algorithm 2's stopping rule was not met within some budget.
    unmet = {
        m: sorted(
            s for s, r in recs.items() if any(STOPPING_RULE in w for p in r["curve"] for w in p.get("warnings", []))
        )
        for m, recs in records.items()
    }
    experiment: dict[str, Any] = {
        "algorithm2_not_met": {m: seeds for m, seeds in unmet.items() if seeds},
        "reference_return": reference,
        "methods": out_methods,
        "source_seeds": source_seeds,
        "random_returns": [sources[s]["random_return"] for s in source_seeds],
        "source_samples": [sources[s]["source_samples"] for s in source_seeds],
        "mapping_target_samples": [sources[s]["mapping_target_samples"] for s in source_seeds],
        "mapping_source_samples": [sources[s]["mapping_source_samples"] for s in source_seeds],
        "source_timings": [sources[s]["timings"] for s in source_seeds],
    }
    comparison = compare(experiment, methods)
    for result in comparison.methods:
        # Per finished seed (not only the shared ones), against the shared-seed threshold.
        curve = out_methods[result.method]["curve"]
        for key, accounting in (("samples_to_threshold", _counted), ("samples_to_threshold_paper", _paper)):
            out_methods[result.method][key] = [
                _json_samples(samples_to_threshold(curve["samples"], returns, comparison.threshold, counts))
                if comparison.meaningful
                else None
                for returns, counts in zip(curve["mean_return"], accounting(curve))
            ]
    experiment.update(
        {
            "compared_seeds": list(comparison.seeds),
            "seed_sets_differ": comparison.seed_sets_differ,
            "random_return": comparison.random_return,
            "best_method": comparison.best_method,
            "threshold": comparison.threshold,
            "threshold_meaningful": comparison.meaningful,
        }
    )
    return experiment


def _counted(curve: dict) -> list[list[float]]:
    """Per seed and budget, every real-target transition counted (the primary accounting)."""
    return curve["target_transitions"]


def _paper(curve: dict) -> list[list[float]]:
    """Per seed and budget, the paper's accounting: the counted transitions but the policy rollouts."""
    return [
        [t - r for t, r in zip(ts, rs)] for ts, rs in zip(curve["target_transitions"], curve["rollout_transitions"])
    ]


def _read_records(
    run_dir: RunDirectory, name: str, seeds: list[int], methods: list[str]
) -> tuple[dict[int, dict], dict[str, dict[int, dict]]]:
    """The experiment's source records by seed, and each method's records by seed (those present)."""
    sources = {}
    for seed in seeds:
        path = run_dir.record_path(name, seed, "source")
        if path.exists():
            sources[seed] = read_record(path)
    records: dict[str, dict[int, dict]] = {m: {} for m in methods}
    for m in methods:
        for seed in seeds:
            path = run_dir.record_path(name, seed, m)
            if path.exists():
                records[m][seed] = read_record(path)
    return sources, records


def _method_entry(recs: dict[int, dict]) -> dict[str, Any]:
    """One method's summary from its records by seed (at least one): curves, finals and extras."""
    seeds_done = sorted(recs)
    curves = [recs[s]["curve"] for s in seeds_done]
    return {
        "seeds": seeds_done,
        "final_return": [recs[s]["final_return"] for s in seeds_done],
        "curve": {
            "samples": [p["samples"] for p in curves[0]],
            "mean_return": [[p["mean_return"] for p in c] for c in curves],  # [seed][budget]
            "mean_steps": [[p["mean_steps"] for p in c] for c in curves],
            # Every real-target transition counted at each budget ([seed][budget]).
            "target_transitions": [[p["target_transitions"] for p in c] for c in curves],
            # Of those, the real-target transitions of policy rollouts (Algorithm 2's U_M): the
            # paper's accounting leaves them out ([seed][budget]).
            "rollout_transitions": [[p["rollout_transitions"] for p in c] for c in curves],
        },
        "data": recs[seeds_done[0]]["data"],
        # Per seed, each evaluation episode's steps at the largest budget.
        "final_steps": {str(s): recs[s]["curve"][-1]["steps"] for s in seeds_done},
        # Per seed, each evaluation episode's steadiness at the largest budget (where declared).
        "final_steadiness": {
            str(s): recs[s]["curve"][-1]["steadiness"] for s in seeds_done if "steadiness" in recs[s]["curve"][-1]
        },
        "extra": {
            k: [recs[s].get(k) for s in seeds_done]
            for k in ("algorithm2_samples",)
            if any(k in recs[s] for s in seeds_done)
        },
        "wall_s": [recs[s].get("wall_s") for s in seeds_done],
        # Per seed whose record is another experiment's (a variant's method without a source).
        "shared_from": {str(s): recs[s]["shared_from"] for s in seeds_done if "shared_from" in recs[s]},
    }


STOPPING_RULE = "apprentice stopping rule"  # the start of Algorithm 2's not-met warning


def known_kernels(summary: dict) -> dict[str, int]:
    """The run's sets of arithmetic kernels with their record counts, but records older than the field."""
    return {k: n for k, n in (summary.get("kernels") or {}).items() if k != UNKNOWN_KERNELS}


def notes(summary: dict) -> list[str]:
    """One line per experiment where Algorithm 2's stopping rule was not met, and one where
    the run's records come from more than one set of arithmetic kernels, each saying what
    it means."""
    lines = []
    kernels = known_kernels(summary)
    if len(kernels) > 1:
        counts = "; ".join(f"[{k}]: {n} records" for k, n in sorted(kernels.items()))
        lines.append(
            f"note: this run's records were computed with {len(kernels)} sets of arithmetic kernels ({counts}), "
            "as when a run resumes on another machine: per-seed returns can differ between them, verdicts should "
            'not; to rerun on one set, see docs/protocol.md, "Across machines"'
        )
    for name, exp in summary["experiments"].items():
        unmet = exp.get("algorithm2_not_met") or {}
        if unmet:
            counts = ", ".join(f"{m} on {len(s)} of {len(exp['methods'][m]['seeds'])} seeds" for m, s in unmet.items())
            lines.append(
                f"note: {name}: Algorithm 2's stopping rule (U_M - U_Mhat <= zeta) was not met within some "
                f"budget ({counts}); the apprentice then uses every sample of that budget, as counted: "
                "expected where the model never matches the target closely, not an error"
            )
    return lines


def _steadiness(experiment: dict) -> None:
    """Per method, each steadiness measure at the largest budget: per seed the mean over its
    evaluation episodes, and the IQM over the compared seeds whose records carry it, with
    its interval, in place."""
    compared = compare(experiment).seeds
    for data in experiment["methods"].values():
        # The compared seeds whose records carry it (where the target declares it).
        seeds = [s for s in compared if str(s) in data["final_steadiness"]]
        per_seed = [data["final_steadiness"][str(s)] for s in seeds]
        if not seeds:
            continue
        data["steadiness_seeds"] = seeds
        data["steadiness"] = {
            name: {**stats.iqm_interval([means]).as_dict(), "per_seed": means.tolist()}
            for name in per_seed[0]
            for means in [np.array([np.mean(v[name]) for v in per_seed])]
        }


def _falls(spec: dict) -> bool:
    """Whether the spec's target ends an episode early only by failing (a fall): survival
    to the cap is then a measure of the policy (``TaskDescription.falls``)."""
    from tatl_mj import suite

    target = spec.get("target") or {}
    try:
        return bool(suite.describe(target["domain"], target["task"], target.get("task_kwargs") or {}).falls)
    except (KeyError, TypeError, ValueError, suite.DomainError):
        return False


def _survival(experiment: dict, cap: int | None) -> None:
    """Kaplan-Meier survival of each method's evaluation episodes at its largest budget, pooled
    over the compared seeds and censored at the episode cap, where any episode ended early."""
    if cap is None:
        return
    seeds = list(compare(experiment).seeds)
    if not seeds:
        return
    for data in experiment["methods"].values():
        lengths = np.concatenate([np.asarray(data["final_steps"][str(s)], dtype=np.float64) for s in seeds])
        times, probability = stats.survival(lengths, cap)
        if len(times):
            data["survival"] = {
                "steps": times.tolist(),
                "probability": probability.tolist(),
                "at_cap": float(probability[-1]),
                "episodes": int(len(lengths)),
                "seeds": seeds,
            }


def _statistics(experiment: dict, spec: dict) -> None:
    """Normalised scores, IQM intervals, the verdict questions' per-seed statistics and the
    declared pairs' verdicts (``verdicts.judge``), in place."""
    reference = experiment.get("reference_return")
    methods = experiment["methods"]
    comparison = compare(experiment)
    seeds = list(comparison.seeds)
    if reference is None or not seeds:
        return
    random_by_seed = _random_by_seed(experiment) or {}
    if any(reference <= random_by_seed[s] for s in seeds):
        experiment["statistics_note"] = "the reference return is not above the random policy's: no normalised scores"
        return
    randoms = np.array([random_by_seed[s] for s in seeds])
    budgets = [float(b) for b in next(iter(methods.values()))["curve"]["samples"]]
    per_seed: dict[str, dict[str, np.ndarray]] = {q: {} for q in verdicts.QUESTIONS}
    paper: dict[str, np.ndarray] = {}
    for name, data in methods.items():
        if name not in {r.method for r in comparison.methods}:
            continue
        rows = [data["seeds"].index(s) for s in seeds]
        scores = stats.normalised(np.asarray(data["curve"]["mean_return"])[rows], randoms[:, None], reference)
        accountings = {
            "counted": np.asarray(_counted(data["curve"]), dtype=np.float64)[rows],
            "paper": np.asarray(_paper(data["curve"]), dtype=np.float64)[rows],
        }
        for key, counts in accountings.items():
            # A reference learns nothing from the target: its policy stands from the first budget.
            accountings[key] = np.where(counts > 0, counts, budgets[0])
        data["normalised"] = scores.tolist()
        data["iqm"] = [stats.iqm_interval([scores[:, j]]).as_dict() for j in range(scores.shape[1])]
        final = scores[:, -1]
        data["final_iqm"] = stats.iqm_interval([final]).as_dict()
        areas = {
            key: stats.efficiency_area(
                counts, scores, budgets[0], budgets[-1], verdicts.SCORE_FLOOR, verdicts.BEFORE_FIRST_POLICY
            )
            for key, counts in accountings.items()
        }
        data["efficiency"] = {**stats.iqm_interval([areas["counted"]]).as_dict(), "per_seed": areas["counted"].tolist()}
        data["efficiency_paper"] = {
            **stats.iqm_interval([areas["paper"]]).as_dict(),
            "per_seed": areas["paper"].tolist(),
        }
        # What a method paid before its first policy, on each accounting (median over seeds).
        data["first_policy"] = {key: float(np.median(counts[:, 0])) for key, counts in accountings.items()}
        per_seed[verdicts.FINAL][name], per_seed[verdicts.EFFICIENCY][name] = final, areas["counted"]
        paper[name] = areas["paper"]
    experiment["efficiency_range"] = [budgets[0], budgets[-1]]
    experiment["families"] = pairs.family_sizes(spec)
    experiment["verdicts"] = verdicts.judge(spec, per_seed, paper)


def aggregate(experiments: dict) -> dict:
    """Across experiments: each method's IQM of normalised final scores over every experiment
    and seed it ran (stratified by experiment), with its interval, and its per-run scores.

    A method's rows that are copies of another experiment's here (a mapping variant's methods
    without a source: the same records) are counted once, in the experiment that computed them.
    """
    strata: dict[str, list[np.ndarray]] = {}
    # Strata by experiment name: the bootstrap's draws follow their order, which must not be
    # the order the specs were given in (or the keys' order in summary.json).
    for _, exp in sorted(experiments.items()):
        for name, data in exp["methods"].items():
            shared = data.get("shared_from", {})
            origins = {unit.split("/")[0] for unit in shared.values()}
            if len(shared) == len(data.get("seeds", ())) > 0 and origins <= set(experiments):
                continue
            if "normalised" in data:
                strata.setdefault(name, []).append(np.asarray(data["normalised"])[:, -1])
    return {
        name: {
            **stats.iqm_interval(parts).as_dict(),
            "experiments": len(parts),
            "runs": int(sum(len(p) for p in parts)),
            "scores": np.concatenate(parts).tolist(),
        }
        for name, parts in strata.items()
    }


def _json_samples(value: float) -> int | None:
    return None if math.isinf(value) else int(value)


def _listed_anywhere(method: str, specs: list[dict]) -> bool:
    return any(method in (spec.get("methods") or {}) for spec in specs)


def build(
    run_dir: RunDirectory, *, specs: list[dict], preset: str, seeds: list[int], methods: list[str], **extra: Any
) -> dict:
    """The summary of a run folder: one entry per spec (see :func:`compare` for the fields used)."""
    experiments = {}
    for spec in specs:
        # Each experiment compares the methods its spec lists (and any the run added to all).
        listed = list(spec.get("methods") or {})
        own = [m for m in methods if m in listed or not _listed_anywhere(m, specs)]
        reference = ((spec.get("presets") or {}).get(preset) or {}).get("reference_return")
        experiment = _experiment(run_dir, spec["name"], seeds, own, reference)
        _statistics(experiment, spec)
        if _falls(spec):
            _survival(experiment, ((spec.get("presets") or {}).get(preset) or {}).get("evaluation_steps"))
        _steadiness(experiment)
        experiments[spec["name"]] = {**experiment, "spec": spec}
    return {
        "experiments": experiments,
        "aggregate": aggregate(experiments),
        "preset": preset,
        "seeds": seeds,
        "methods": methods,
        "threshold_fraction": THRESHOLD_FRACTION,
        "reference_threshold": REFERENCE_THRESHOLD,
        "verdict_rule_version": verdicts.VERDICT_RULE_VERSION,
        "schema_version": SCHEMA_VERSION,
        **extra,
    }
