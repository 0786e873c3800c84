"""Aggregates a run's finished records into DIR/summary.json (:func:`build`; the file's content is
read back through :mod:`tatl_mj.experiments.results.summary_data`).

Per experiment: each method's curves and finals per finished seed, the comparison over the seeds
every method finished (:mod:`tatl_mj.experiments.results.comparison`: the threshold and the
transitions to it), and with a reference return the verdict rule's statistics
(:mod:`tatl_mj.experiments.results.verdicts`): per method and budget the IQM of the normalised
score with its 95% stratified-bootstrap interval (:mod:`tatl_mj.experiments.results.statistics`),
the efficiency areas on both accountings, and the verdicts of the pairs the spec declares. Then
survival and steadiness (:mod:`tatl_mj.experiments.results.notes`), and across experiments each
method's normalised final score (:func:`aggregate`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from tatl_mj.experiments.results import notes, pairs, verdicts
from tatl_mj.experiments.results import statistics as stats
from tatl_mj.experiments.results.comparison import (
    REFERENCE_THRESHOLD,
    THRESHOLD_FRACTION,
    compare_methods,
    samples_to_threshold,
)
from tatl_mj.experiments.results.records import SCHEMA_VERSION, RunDirectory, read_record
from tatl_mj.experiments.results.summary_data import MethodSummary


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
            s
            for s, r in recs.items()
            if any(notes.STOPPING_RULE in w for p in r["curve"] for w in p.get("warnings", []))
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
    typed = {m: MethodSummary.from_json(entry) for m, entry in out_methods.items()}
    comparison = compare_methods(typed, _random_by_seed(experiment), reference, methods)
    for result in comparison.methods:
        # Per finished seed (not only the shared ones), against the shared-seed threshold.
        curve = out_methods[result.method]["curve"]
        for key, accounting in (
            ("samples_to_threshold", verdicts.COUNTED),
            ("samples_to_threshold_paper", verdicts.PAPER),
        ):
            counted = verdicts.transitions(curve["target_transitions"], curve["rollout_transitions"], accounting)
            out_methods[result.method][key] = [
                _json_samples(samples_to_threshold(curve["samples"], returns, comparison.threshold, counts))
                if comparison.meaningful
                else None
                for returns, counts in zip(curve["mean_return"], counted)
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
            # The shared samples the method kept at each budget (TA-TL: the apprentice's, those
            # Algorithm 2 stopped at), [seed][budget]; a record without them: the budget.
            "samples_used": [[p.get("samples_used", p["samples"]) for p in c] for c in curves],
        },
        "data": recs[seeds_done[0]]["data"],
        # The theorem's premises per seed and budget (a point's ``premises``), None where no
        # point has any (a method that is not TA-TL): report.premises reads them.
        "premises": [[p.get("premises") for p in c] for c in curves]
        if any(p.get("premises") for c in curves for p in c)
        else None,
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


def add_statistics(experiment: dict, spec: dict, seeds: list[int]) -> None:
    """Normalised scores, IQM intervals, the verdict questions' per-seed statistics
    (``verdicts.scored``) and the declared pairs' verdicts (``verdicts.judge``) on the compared
    ``seeds``, in place."""
    reference = experiment.get("reference_return")
    methods = experiment["methods"]
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
        if not set(seeds) <= set(data["seeds"]):
            continue
        rows = [data["seeds"].index(s) for s in seeds]
        curve = {k: np.asarray(data["curve"][k])[rows] for k in ("mean_return", "target_transitions")}
        rollouts = np.asarray(data["curve"]["rollout_transitions"])[rows]
        scored = verdicts.scored(
            curve["mean_return"], randoms, reference, curve["target_transitions"], rollouts, budgets
        )
        scores, areas = scored.normalised, scored.efficiency
        data["normalised"] = scores.tolist()
        data["iqm"] = [stats.iqm_interval([scores[:, j]]).as_dict() for j in range(scores.shape[1])]
        data["final_iqm"] = stats.iqm_interval([scored.final]).as_dict()
        for key, accounting in (("efficiency", verdicts.COUNTED), ("efficiency_paper", verdicts.PAPER)):
            data[key] = {**stats.iqm_interval([areas[accounting]]).as_dict(), "per_seed": areas[accounting].tolist()}
        # What a method paid before its first policy, on each accounting (median over seeds).
        data["first_policy"] = scored.first_policy
        per_seed[verdicts.FINAL][name], per_seed[verdicts.EFFICIENCY][name] = scored.final, areas[verdicts.COUNTED]
        paper[name] = areas[verdicts.PAPER]
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
    """The summary of a run folder: one entry per spec (``comparison.compare_methods`` for the fields used)."""
    experiments = {}
    for spec in specs:
        # Each experiment compares the methods its spec lists (and any the run added to all).
        listed = list(spec.get("methods") or {})
        own = [m for m in methods if m in listed or not _listed_anywhere(m, specs)]
        reference = ((spec.get("presets") or {}).get(preset) or {}).get("reference_return")
        experiment = _experiment(run_dir, spec["name"], seeds, own, reference)
        add_statistics(experiment, spec, experiment["compared_seeds"])
        if notes.falls(spec):
            notes.survival(experiment, ((spec.get("presets") or {}).get(preset) or {}).get("evaluation_steps"))
        notes.steadiness(experiment)
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
