"""Aggregates finished records into DIR/summary.json.

The convergence threshold is defined once per experiment and applied to every
method alike: ``threshold = R_random + 0.95 (R_best - R_random)``, where
``R_best`` is the best method's final average return (mean over seeds, at the
largest budget) and ``R_random`` the uniformly random policy's average return
under the same evaluation protocol. A method's ``samples_to_threshold`` for a
seed is the smallest budget whose average return reaches the threshold, or
``null`` if it never does.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from tatl_mj.experiments.records import RunDirectory, read_json

THRESHOLD_FRACTION = 0.95


def samples_to_threshold(curve: list[dict], threshold: float) -> int | None:
    for point in curve:
        if point["mean_return"] >= threshold:
            return point["samples"]
    return None


def _experiment(run_dir: RunDirectory, name: str, seeds: list[int], methods: list[str]) -> dict:
    sources = {}
    for seed in seeds:
        path = run_dir.record_path(name, seed, "source")
        if path.exists():
            sources[seed] = read_json(path)
    records: dict[str, dict[int, dict]] = {m: {} for m in methods}
    for m in methods:
        for seed in seeds:
            path = run_dir.record_path(name, seed, m)
            if path.exists():
                records[m][seed] = read_json(path)
    random_return = float(np.mean([s["random_return"] for s in sources.values()])) if sources else None
    finals = {m: float(np.mean([r["final_return"] for r in recs.values()])) for m, recs in records.items() if recs}
    best_method = max(finals, key=finals.get) if finals else None
    threshold = None
    if best_method is not None and random_return is not None:
        threshold = random_return + THRESHOLD_FRACTION * (finals[best_method] - random_return)
    out_methods = {}
    for m, recs in records.items():
        seeds_done = sorted(recs)
        if not seeds_done:
            continue
        curves = [recs[s]["curve"] for s in seeds_done]
        out_methods[m] = {
            "seeds": seeds_done,
            "final_return": [recs[s]["final_return"] for s in seeds_done],
            "samples_to_threshold": [
                samples_to_threshold(c, threshold) if threshold is not None else None for c in curves
            ],
            "curve": {
                "samples": [p["samples"] for p in curves[0]],
                "mean_return": [[p["mean_return"] for p in c] for c in curves],  # [seed][budget]
                "mean_steps": [[p["mean_steps"] for p in c] for c in curves],
            },
            "extra": {k: [recs[s].get(k) for s in seeds_done] for k in ("algorithm2_samples",) if any(
                k in recs[s] for s in seeds_done)},
            "wall_s": [recs[s].get("wall_s") for s in seeds_done],
        }
    return {
        "methods": out_methods,
        "random_return": random_return,
        "best_method": best_method,
        "threshold": threshold,
        # With no method above the random policy, "reaching the threshold" says nothing.
        "threshold_meaningful": bool(best_method is not None and random_return is not None
                                     and finals[best_method] > random_return),
        "source_samples": [sources[s]["source_samples"] for s in sorted(sources)],
        "mapping_target_samples": [sources[s]["mapping_target_samples"] for s in sorted(sources)],
        "mapping_source_samples": [sources[s]["mapping_source_samples"] for s in sorted(sources)],
        "source_timings": [sources[s]["timings"] for s in sorted(sources)],
    }


def build(run_dir: RunDirectory, *, specs: list[dict], preset: str, seeds: list[int], methods: list[str],
          **extra: Any) -> dict:
    experiments = {}
    for spec in specs:
        experiments[spec["name"]] = {**_experiment(run_dir, spec["name"], seeds, methods), "spec": spec}
    return {"experiments": experiments, "preset": preset, "seeds": seeds, "methods": methods,
            "threshold_fraction": THRESHOLD_FRACTION, **extra}
