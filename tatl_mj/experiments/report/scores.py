"""Score panels over a sweep's conditions (``tatl plot`` on ``tatl evaluate`` folders): one panel per
policy, evaluated ones (``tatl evaluate``) and a run's built-in methods alike, on one shared y scale,
each titled with the target transitions its policy learned from.

A panel shows, per condition, every seed's normalised score (0: the random policy, 1: the
preset's reference return) as a dot and their IQM as a bar: an evaluated policy's from its
scores.json, a method's final budget's from the run's summary.json (the same random and
reference returns).
"""

from __future__ import annotations

import dataclasses
import textwrap
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from tatl_mj.experiments.report.credit_maps import sweeps
from tatl_mj.experiments.report.figures import NORMALISED_LABEL
from tatl_mj.experiments.report.style import compact, method_colors, method_label, order
from tatl_mj.experiments.results import statistics
from tatl_mj.experiments.results.summary_data import Summary
from tatl_mj.experiments.run import scoring


@dataclasses.dataclass(frozen=True)
class Panel:
    """One policy's normalised scores: ``scores[i]`` the seeds' at condition ``conditions[i]``."""

    name: str
    conditions: tuple[str, ...]
    scores: tuple[tuple[float, ...], ...]
    transitions: tuple[float, ...] = ()  # the target transitions it learned from, per seed (any condition)

    def title(self) -> str:
        """Its name and the target transitions it learned from (a range where they differ)."""
        if not self.transitions:
            return f"{self.name}\n(target transitions not given)"
        low, high = min(self.transitions), max(self.transitions)
        count = compact(low) if low == high else f"{compact(low)}-{compact(high)}"
        return f"{self.name}\n{count} target transitions"


def condition_label(condition: dict) -> str:
    """``{"gain": 0.5}`` -> ``gain=0.5``."""
    return ", ".join(f"{k}={v:g}" if isinstance(v, (int, float)) else f"{k}={v}" for k, v in condition.items())


def evaluation_panel(folder: str | Path) -> tuple[str, Panel]:
    """A ``tatl evaluate`` folder's panel, with the experiment (sweep) it scored."""
    scores = scoring.read_scores(folder)
    manifest, rows = scores["manifest"], scores["rows"]
    names, labels, by = [], [], {}
    for row in rows:
        if row["experiment"] not in by:
            names.append(row["experiment"])
            labels.append(condition_label(row["condition"]) or row["experiment"])
            by[row["experiment"]] = []
        by[row["experiment"]].append(np.nan if row["normalised"] is None else row["normalised"])
    given = manifest.get("transitions")
    panel = Panel(
        name=str(manifest.get("name") or Path(folder).name),
        conditions=tuple(labels),
        scores=tuple(tuple(by[n]) for n in names),
        transitions=() if given is None else (float(given),),
    )
    return str(manifest["experiment"]), panel


def method_panels(summary: Summary, sweep: str, methods: Sequence[str] | None = None) -> list[Panel]:
    """The run's methods over sweep ``sweep``'s conditions: each seed's final normalised score,
    titled with the target transitions its final budget counted (Algorithm 2's rollouts included)."""
    cells = sweeps(summary).get(sweep)
    if not cells and sweep in summary.experiments:  # an experiment without a sweep: its one target
        cells = [({}, summary.experiments[sweep])]
    if not cells:
        raise ValueError(f"the run has no experiment or sweep {sweep!r}; it has {sorted(summary.experiments)}")
    present = [m for m in summary.methods if all(m in exp.methods for _, exp in cells)]
    chosen = sorted(present, key=order) if methods is None else list(methods)
    missing = [m for m in chosen if m not in present]
    if missing:
        raise ValueError(f"method(s) {missing} not in every condition of {sweep}; the run has {present}")
    panels = []
    for method in chosen:
        scores, counts = [], []
        for _, exp in cells:
            result = exp.methods[method]
            if result.normalised is None:
                raise ValueError(f"{exp.name}: {method} has no normalised scores (no reference return)")
            scores.append(tuple(float(row[-1]) for row in result.normalised))
            counts += [float(row[-1]) for row in result.curve.target_transitions]
        labels = tuple(condition_label(c) or exp.name for c, exp in cells)
        panels.append(Panel(method_label(method), labels, tuple(scores), tuple(counts)))
    return panels


def figure(panels: Sequence[Panel], path: str | Path, title: str) -> Path:
    """One panel per policy, side by side on one shared y scale; returns ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not panels:
        raise ValueError("no panel to draw")
    conditions = panels[0].conditions
    for panel in panels:
        if panel.conditions != conditions:
            raise ValueError(f"{panel.name} scores conditions {list(panel.conditions)}, not {list(conditions)}")
    colors = method_colors([p.name for p in panels])
    width = max(3.2, 0.9 * len(conditions) + 1.4)
    fig, axes = plt.subplots(1, len(panels), figsize=(width * len(panels), 4.2), sharey=True, squeeze=False)
    x = np.arange(len(conditions))
    for ax, panel in zip(axes[0], panels):
        for i, seeds in enumerate(panel.scores):
            values = np.array(seeds, dtype=np.float64)
            values = values[np.isfinite(values)]
            spread = np.linspace(-0.15, 0.15, len(values)) if len(values) > 1 else np.zeros(len(values))
            ax.scatter(x[i] + spread, values, s=14, color=colors[panel.name], alpha=0.55, zorder=3)
            if len(values):
                ax.hlines(float(statistics.iqm(values)), x[i] - 0.25, x[i] + 0.25, color="black", lw=2, zorder=4)
        ax.axhline(0.0, color="grey", lw=0.8, ls=":")
        ax.axhline(1.0, color="grey", lw=0.8, ls="--")
        ax.set_xticks(x, conditions, rotation=30 if len(conditions) > 4 else 0)
        ax.set_xlim(-0.6, len(conditions) - 0.4)
        ax.set_title(panel.title(), fontsize=9)
        ax.grid(alpha=0.3, axis="y")
    axes[0][0].set_ylabel(NORMALISED_LABEL, fontsize=8)
    fig.suptitle(title, fontsize=10)
    caption = (
        "Dots: the seeds' normalised scores; bar: their IQM; dotted line: the random policy; dashed: the reference."
    )
    fig.text(0.5, 0.01, textwrap.fill(caption, int(13 * width * len(panels))), ha="center", va="bottom", fontsize=7)
    fig.tight_layout(rect=(0, 0.09, 1, 1))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_scores(folders: Sequence[str | Path], out: str | Path, methods: Sequence[str] | None = None) -> Path:
    """The score figure of ``tatl evaluate`` folders, and of one ``tatl run`` folder's methods
    where one is among ``folders`` (``methods``: which; default all), written to ``out``."""
    evaluated, runs = [], []
    for folder in folders:
        if scoring.is_evaluation(folder):
            evaluated.append(evaluation_panel(folder))
        elif (Path(folder) / "summary.json").exists():
            runs.append(Path(folder))
        else:
            raise FileNotFoundError(f"{folder} is neither a tatl evaluate folder nor a tatl run folder")
    if len(runs) > 1:
        raise ValueError(f"give at most one run folder with evaluate folders, got {[str(r) for r in runs]}")
    sweeps_named = sorted({name for name, _ in evaluated})
    if len(sweeps_named) != 1:
        raise ValueError(f"the evaluate folders must score one spec, they score {sweeps_named}")
    panels = [panel for _, panel in evaluated]
    if runs:
        from tatl_mj.experiments.results import summary_data

        summary = summary_data.read(runs[0] / "summary.json")
        panels = method_panels(summary, sweeps_named[0], methods) + panels
    return figure(panels, out, sweeps_named[0])


__all__ = ["Panel", "condition_label", "evaluation_panel", "figure", "method_panels", "plot_scores"]
