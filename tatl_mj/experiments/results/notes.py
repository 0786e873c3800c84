"""What a summary says beside the verdicts: Algorithm 2's stopping rule not met, more than one set of
arithmetic kernels (``notes``, printed after a run), and, written into each experiment, survival
to the episode cap and steadiness at the largest budget (``survival``, ``steadiness``)."""

from __future__ import annotations

import numpy as np

from tatl_mj.experiments.results import statistics as stats
from tatl_mj.experiments.results.comparison import comparison_of
from tatl_mj.experiments.results.summary_data import Experiment, Summary

STOPPING_RULE = "apprentice stopping rule"  # the start of Algorithm 2's not-met warning


def notes(summary: Summary) -> list[str]:
    """One line per experiment where Algorithm 2's stopping rule was not met, and one where
    the run's records come from more than one set of arithmetic kernels, each saying what
    it means."""
    lines = []
    kernels = summary.known_kernels
    if len(kernels) > 1:
        counts = "; ".join(f"[{k}]: {n} records" for k, n in sorted(kernels.items()))
        lines.append(
            f"note: this run's records were computed with {len(kernels)} sets of arithmetic kernels ({counts}), "
            "as when a run resumes on another machine: per-seed returns can differ between them, verdicts should "
            'not; to rerun on one set, see docs/protocol.md, "Across machines"'
        )
    for name, exp in summary.experiments.items():
        unmet = exp.algorithm2_not_met
        if unmet:
            counts = ", ".join(f"{m} on {len(s)} of {len(exp.methods[m].seeds)} seeds" for m, s in unmet.items())
            lines.append(
                f"note: {name}: Algorithm 2's stopping rule (U_M - U_Mhat <= zeta) was not met within some "
                f"budget ({counts}); the apprentice then uses every sample of that budget, as counted: "
                "expected where the model never matches the target closely, not an error"
            )
    return lines


def _compared_seeds(experiment: dict) -> tuple[int, ...]:
    """The seeds every method of a summary experiment being written finished."""
    return comparison_of(Experiment.from_json("", experiment)).seeds


def steadiness(experiment: dict) -> None:
    """Per method, each steadiness measure at the largest budget: per seed the mean over its
    evaluation episodes, and the IQM over the compared seeds whose records carry it, with
    its interval, in place."""
    compared = _compared_seeds(experiment)
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


def falls(spec: dict) -> bool:
    """Whether the spec's target ends an episode early only by failing (a fall): survival
    to the cap is then a measure of the policy (``TaskDescription.falls``)."""
    from tatl_mj import suite

    target = spec.get("target") or {}
    try:
        return bool(suite.describe(target["domain"], target["task"], target.get("task_kwargs") or {}).falls)
    except (KeyError, TypeError, ValueError, suite.DomainError):
        return False


def survival(experiment: dict, cap: int | None) -> None:
    """Kaplan-Meier survival of each method's evaluation episodes at its largest budget, pooled
    over the compared seeds and censored at the episode cap, where any episode ended early."""
    if cap is None:
        return
    seeds = list(_compared_seeds(experiment))
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


__all__ = ["STOPPING_RULE", "falls", "notes", "steadiness", "survival"]
