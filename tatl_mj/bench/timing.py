"""The fastest of repeated timings, taken in turn, and paired ratios between them."""

from __future__ import annotations

from typing import Any

import numpy as np


def fastest_of(timers: dict[str, Any], repeats: int) -> dict[str, dict[str, Any]]:
    """Each timer's fastest of ``repeats`` runs, the timers taken in turn.

    Other tenants slow a shared machine by up to 2x for seconds at a time; taking
    the paths in turn and keeping each one's best lets them see the same
    machine. Each record notes the slowest rate too (``slowest_steps_per_s``).
    """
    runs: dict[str, list[dict[str, Any]]] = {path: [] for path in timers}
    for _ in range(repeats):
        for path, timer in timers.items():
            runs[path].append(timer())
    figures = {}
    for path, records in runs.items():
        best = max(records, key=lambda r: r["steps_per_s"])
        figures[path] = {
            **best,
            "repeats": repeats,
            "slowest_steps_per_s": min(r["steps_per_s"] for r in records),
            "each_steps_per_s": [r["steps_per_s"] for r in records],  # in the order taken
        }
    return figures


def paired(figures: dict[str, dict[str, Any]], path: str, against: str) -> float:
    """The median over repeats of ``path``'s rate over ``against``'s timed right beside it: the
    machine's drift between repeats cancels."""
    return float(np.median(np.divide(figures[path]["each_steps_per_s"], figures[against]["each_steps_per_s"])))
