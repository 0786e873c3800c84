"""Why TA-TL does what it does on each experiment: the theorem's premises, from summary.json.

Each TA-TL method's curve points carry the premises measured on their evaluation
episodes (record schema 3; docs/protocol.md, "The theorem's premises, measured").
Here: per experiment and method, the median over seeds at the largest budget of
each measure and the premises it fails by the declared thresholds
(:func:`aggregate`); the markdown "why" table (:func:`why_table`); and a figure,
one panel per measure, experiments along the axis, the threshold drawn
(:func:`premises_figure`). Summaries without premises (older records) give
nothing: the table is empty and no figure is drawn.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from tatl_mj.experiments.report import tables
from tatl_mj.experiments.results.summary_data import Summary
from tatl_mj.transfer import premises

WHY_METHODS = (*tables.READINGS, "ta-tl-h", "ta-tl-replan")
"""The methods the "why" table explains, in its order: both readings of TA-TL's action, then the
bicycle's horizon-matched and the grid's replanning TA-TL."""
MEASURES = tuple(f.name for f in dataclasses.fields(premises.PremiseMeasurements))
"""Every measure a record's ``premises`` holds."""


@dataclasses.dataclass(frozen=True)
class PremiseRow:
    """One method of one experiment: its median measures over seeds at the largest budget.

    Attributes:
      experiment, method: the names.
      measured: the median of each measure over the seeds that measured it (None: none did).
      failed: the premises above their thresholds (``premises.failed``), in the thresholds' order.
      seeds: how many seeds had premises at the largest budget.
    """

    experiment: str
    method: str
    measured: premises.PremiseMeasurements
    failed: tuple[str, ...]
    seeds: int


def _median(values: Sequence[float | None]) -> float | None:
    present = [v for v in values if v is not None]
    return float(np.median(present)) if present else None


def aggregate(
    summary: Summary, methods: Sequence[str] | None = None, experiments: Sequence[str] | None = None
) -> list[PremiseRow]:
    """Per experiment (summary order; ``experiments``: only these) and method with premises
    (``methods``: only these, in that order), the medians at the largest budget and the failed premises."""
    rows = []
    for name, experiment in summary.experiments.items():
        if experiments is not None and name not in experiments:
            continue
        names = [m for m in (methods or experiment.methods) if m in experiment.methods]
        for method in names:
            per_seed = experiment.methods[method].premises
            if per_seed is None:
                continue
            last = [row[-1] for row in per_seed if row and row[-1] is not None]
            if not last:
                continue
            measured = premises.PremiseMeasurements(**{k: _median([p.get(k) for p in last]) for k in MEASURES})
            rows.append(PremiseRow(name, method, measured, premises.failed(measured), len(last)))
    return rows


def _value(x: float) -> str:
    return f"{x:.3g}"


def why_line(row: PremiseRow, thresholds: premises.PremiseThresholds = premises.THRESHOLDS) -> str:
    """``infeasible 0.97 > 0.5; delta 3.1 > 0.5``, or ``none fails``."""
    if not row.failed:
        return "none fails"
    parts = []
    for name in row.failed:
        value = getattr(row.measured, name)
        parts.append(f"{name} {_value(value)} > {_value(getattr(thresholds, name))}")
    return "; ".join(parts)


def why_table(summary: Summary, methods: Sequence[str] = WHY_METHODS, experiments: Sequence[str] | None = None) -> str:
    """The markdown "why" table: one line per experiment and method, the premises it fails
    (median over seeds at the largest budget) against their thresholds. Empty where the
    summary has no premises."""
    rows = aggregate(summary, methods, experiments)
    if not rows:
        return ""
    lines = [
        "| experiment | method | seeds | premises failed (median at the largest budget > threshold) |",
        "|---|---|---|---|",
    ]
    lines += [f"| {r.experiment} | {r.method} | {r.seeds} | {why_line(r)} |" for r in rows]
    return "\n".join(lines) + "\n"


def has_premises(summary: Summary) -> bool:
    """Whether any method of the summary carries premises."""
    return any(m.premises is not None for e in summary.experiments.values() for m in e.methods.values())


def premises_figure(summary: Summary, path: str | Path, methods: Sequence[str] = WHY_METHODS) -> Path | None:
    """One panel per judged measure, experiments along the axis, each method's median at
    the largest budget, the declared threshold dashed; None (nothing drawn) without premises."""
    rows = aggregate(summary, methods)
    if not rows:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    judged = [f.name for f in dataclasses.fields(premises.THRESHOLDS)]
    shown = [m for m in judged if any(getattr(r.measured, m) is not None for r in rows)]
    experiments = list(dict.fromkeys(r.experiment for r in rows))
    names = list(dict.fromkeys(r.method for r in rows))
    cols = min(4, len(shown))
    n_rows = math.ceil(len(shown) / cols)
    fig, axes = plt.subplots(n_rows, cols, figsize=(3.6 * cols, 2.8 * n_rows + 0.8), squeeze=False)
    x = np.arange(len(experiments))
    width = 0.8 / max(len(names), 1)
    for ax, measure in zip(axes.flat, shown):
        for k, method in enumerate(names):
            by = {r.experiment: getattr(r.measured, measure) for r in rows if r.method == method}
            y = np.array([np.nan if by.get(e) is None else by[e] for e in experiments], dtype=float)
            ax.bar(x + (k - (len(names) - 1) / 2) * width, y, width, label=method)
        ax.axhline(getattr(premises.THRESHOLDS, measure), color="k", linestyle="--", linewidth=1)
        ax.set_yscale("symlog", linthresh=1e-3)
        ax.set_title(measure)
        ax.set_xticks(x, experiments, rotation=30, ha="right", fontsize=7)
    for ax in list(axes.flat)[len(shown) :]:
        ax.set_visible(False)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    # The title on top, the legend under it, the panels below both (none overlapping).
    fig.suptitle("The theorem's premises (median over seeds, largest budget; dashed: threshold)", y=0.995, fontsize=9)
    fig.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.955), ncol=len(names), frameon=False)
    fig.tight_layout(rect=(0, 0, 1, 0.9))
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def measurements(values: Mapping[str, float | None]) -> premises.PremiseMeasurements:
    """A record's ``premises`` object as :class:`~tatl_mj.transfer.premises.PremiseMeasurements`
    (the failed list is derived, never stored)."""
    return premises.PremiseMeasurements(**{k: values.get(k) for k in MEASURES})


__all__ = [
    "MEASURES",
    "WHY_METHODS",
    "PremiseRow",
    "aggregate",
    "has_premises",
    "measurements",
    "premises_figure",
    "why_table",
    "why_line",
]
