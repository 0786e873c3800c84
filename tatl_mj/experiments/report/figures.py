"""`tatl plot`'s figures: per experiment its learning curves on both accountings and its paired
verdicts, and the performance profiles across experiments.

Everything is drawn from the run's summary (:mod:`tatl_mj.experiments.results.summary_data`), so a figure
and the tables show the same seeds and numbers. Where the experiment declares a reference
return (every shipped preset does):

- (a) the IQM over seeds of the normalised score (0: the random policy, 1: the reference
  return) against the real-target transitions counted (Algorithm 2's rollouts included),
  with its 95% stratified-bootstrap band and the threshold (dashed);
- (b) the same against the paper's accounting (the apprentice's samples only);
- (c) each declared pair's paired P(method better on a seed) on both questions, final and
  efficiency, with its exact 95% interval and verdicts.

Every budget's point is drawn: a method whose budgets share one policy and count (Algorithm 2
stopping early) has one marker labelled with how many budgets it stands for, drawn above the
other methods' lines. Without a reference return: (a) per-seed returns with a thick median and
the random policy's return; (b) the target samples each seed needed to reach the relative
threshold ("never" row), or final returns. A caption under the panels defines what is drawn.
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tatl_mj.experiments.report.style import compact, method_colors, method_label, order, spaced_ticks
from tatl_mj.experiments.report.tables import seed_note
from tatl_mj.experiments.results import verdicts
from tatl_mj.experiments.results.comparison import (
    REFERENCE_THRESHOLD,
    THRESHOLD_FRACTION,
    Comparison,
    MethodResult,
    comparison_of,
)
from tatl_mj.experiments.results.summary_data import Experiment, MethodSummary, PairVerdict, Summary

LINE_STYLES = ("-", (0, (5, 2)), (0, (1, 1.5)), (0, (6, 2, 1, 2)))  # cycled, so overlapping curves both show
MARKERS = ("o", "s", "D", "^", "v", "P", "X", "h", "<", ">")  # cycled, so coinciding points both show
RETURN_LABEL = "return (undiscounted episode sum)"  # the y-axis of every return panel
CLIP_SCALES = 6.0  # values beyond this many robust spreads from the bulk are clipped
NORMALISED_LABEL = "normalised score (0: random policy, 1: reference return)"
ACCOUNTINGS = {
    "counted": "real-target transitions counted (median over seeds)",
    "paper": "paper's accounting: apprentice samples (median over seeds)",
}


def axis_limits(
    values: Sequence[float], keep: Sequence[float] = (), scales: float = CLIP_SCALES
) -> tuple[float, float]:
    """y-limits holding the bulk of ``values`` and every one of ``keep`` (reference lines).

    A value more than ``scales`` robust spreads (1.4826 x median absolute
    deviation, at least the span of ``keep``) beyond the bulk is left outside, to
    be drawn clipped; with none left out the limits hold every value.
    """
    values = np.asarray([v for v in values if np.isfinite(v)], dtype=np.float64)
    keep = np.asarray([v for v in keep if v is not None and np.isfinite(v)], dtype=np.float64)
    if values.size == 0 and keep.size == 0:
        return -1.0, 1.0
    pool = np.concatenate([values, keep])
    center = float(np.median(pool))
    spread = 1.4826 * float(np.median(np.abs(pool - center)))
    if keep.size:
        spread = max(spread, float(keep.max() - keep.min()))
    spread = max(spread, 1e-6 * max(1.0, abs(center)))
    low_fence = min([center] + list(keep)) - scales * spread
    high_fence = max([center] + list(keep)) + scales * spread
    inside = pool[(pool >= low_fence) & (pool <= high_fence)]
    low, high = float(inside.min()), float(inside.max())
    pad = 0.06 * (high - low) if high > low else max(1.0, abs(high) * 0.1)
    return low - pad, high + pad


def mark_clipped(ax: Any, x: np.ndarray, y: np.ndarray, limits: tuple[float, float], color: str) -> int:
    """Triangles on the axis edge for values beyond it; returns how many."""
    low, high = limits
    below, above = y < low, y > high
    for beyond, edge, marker in ((below, low, "v"), (above, high, "^")):
        ax.scatter(
            x[beyond],
            np.full(beyond.sum(), edge),
            marker=marker,
            s=28,
            color=color,
            edgecolor="black",
            linewidth=0.5,
            zorder=5,
            clip_on=False,
        )
    return int(below.sum() + above.sum())


def figure(name: str, experiment: Experiment, path: str | Path, methods: Sequence[str] | None = None) -> Path:
    """Draws one experiment's panels and caption to ``path``; returns it (see the module docstring)."""
    if methods is None and any(data.iqm is not None for data in experiment.methods.values()):
        return interval_figure(name, experiment, path)
    return _return_figure(name, experiment, path, methods)


def _iqm_panel(
    ax: Any, experiment: Experiment, methods: list[str], colors: dict[str, str], accounting: str
) -> list[Any]:
    """IQM of each method's normalised score against its median transitions on ``accounting``,
    with the 95% band; returns the legend handles."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles: list[Any] = []
    drawn: list[float] = []
    curves = []
    for i, method in enumerate(methods):
        data = experiment.methods[method]
        x = np.median(data.curve.transitions(accounting), axis=0)
        iqm = data.iqm or ()
        value, low, high = (
            np.array([np.nan if v is None else v for v in values])
            for values in zip(*((e.value, e.low, e.high) for e in iqm))
        )
        curves.append((i, method, x, value, np.where(np.isnan(low), value, low), np.where(np.isnan(high), value, high)))
        drawn += [*value, *low[np.isfinite(low)], *high[np.isfinite(high)]]
        handles.append(Line2D([], [], color=colors[method], lw=2, ls=LINE_STYLES[i % len(LINE_STYLES)],
                              marker=MARKERS[i % len(MARKERS)], ms=5, label=method_label(method)))  # fmt: skip
    low, high = axis_limits(drawn, [0.0, 1.0])
    # Below the efficiency area's floor a score says only "worse than random by the reference's
    # margin": such points are drawn on the edge, so blow-ups do not squash the rest.
    limits = (max(low, verdicts.SCORE_FLOOR - 0.05), high)
    clipped = 0
    # Methods with the fewest distinct points on top, so a curve collapsed onto one point stays visible.
    for i, method, x, value, low, high in sorted(curves, key=lambda c: -len(set(zip(c[2], c[3])))):
        color, style, marker = colors[method], LINE_STYLES[i % len(LINE_STYLES)], MARKERS[i % len(MARKERS)]
        ax.fill_between(x, np.clip(low, *limits), np.clip(high, *limits), color=color, alpha=0.12, lw=0)
        ax.plot(x, np.clip(value, *limits), color=color, lw=1.8, ls=style, zorder=3)
        ax.plot(x, np.clip(value, *limits), ls="none", marker=marker, ms=5.5, color=color, markeredgecolor="white",
                markeredgewidth=0.6, zorder=4)  # fmt: skip
        for (px, py), n in _repeats(x, np.clip(value, *limits)).items():
            ax.annotate(f"x{n}", (px, py), xytext=(4, 4), textcoords="offset points", fontsize=7, color=color, zorder=5)
        clipped += mark_clipped(ax, x, value, limits, color)
    ax.axhline(0.0, color="0.45", ls=":", lw=1.2)
    ax.axhline(1.0, color="0.45", ls="-.", lw=1.0)
    ax.axhline(REFERENCE_THRESHOLD, color="black", ls="--", lw=0.9)
    handles += [
        Patch(color="0.5", alpha=0.3, label="band: 95% CI (stratified bootstrap over seeds)"),
        Line2D([], [], color="0.45", ls=":", lw=1.2, label="random policy (0)"),
        Line2D([], [], color="0.45", ls="-.", lw=1.0, label="reference return (1)"),
        Line2D([], [], color="black", ls="--", lw=0.9, label=f"threshold ({REFERENCE_THRESHOLD})"),
        Line2D([], [], color="white", label="xN: N budgets at one point (the same policy and count)"),
    ]
    if clipped:
        label = f"IQM beyond the axis ({clipped} point{'s' * (clipped > 1)})"
        handles.append(Line2D([], [], color="white", marker="v", markeredgecolor="black", markerfacecolor="0.6",
                              ms=6, lw=0, label=label))  # fmt: skip
    ax.set_ylim(*limits)
    ax.set_xscale("log")
    ticks = spaced_ticks(sorted({float(v) for _, _, x, *_ in curves for v in x}), 0.3)
    title = "(a) counted transitions" if accounting == "counted" else "(b) the paper's accounting"
    _label_curve_axes(ax, ticks, ACCOUNTINGS[accounting], NORMALISED_LABEL, f"{title}: IQM over seeds, 95% band")
    return handles


def _repeats(x: np.ndarray, y: np.ndarray) -> dict[tuple[float, float], int]:
    """Points that stand for more than one budget, with how many."""
    seen: dict[tuple[float, float], int] = {}
    for point in zip(x.tolist(), y.tolist()):
        seen[point] = seen.get(point, 0) + 1
    return {p: n for p, n in seen.items() if n > 1 and all(math.isfinite(v) for v in p)}


def _verdict_panel(ax: Any, experiment: Experiment, colors: dict[str, str]) -> None:
    """Each declared pair's paired P(method better on a seed) with its interval, final (circle)
    and efficiency (square) on one row, and the verdicts beside it."""
    pairs = [p for p in experiment.verdicts or () if not p.parents]
    for row, pair in enumerate(pairs):
        color = colors.get(pair.method, "black")
        said = []
        for question, offset, marker in ((verdicts.FINAL, -0.17, "o"), (verdicts.EFFICIENCY, 0.17, "s")):
            answer = pair.answer(question)
            if answer is None:
                continue
            value, low, high = answer.probability.bounds()
            ax.hlines(row + offset, low, high, color=color, lw=3.5, alpha=0.5)
            ax.plot([value], [row + offset], marker, color=color, markeredgecolor="black", ms=5)
            said.append(f"{question[:3]}.: {verdicts.words(pair.role)[answer.verdict]}")
        ax.text(1.02, row, "\n".join(said), va="center", fontsize=7, transform=ax.get_yaxis_transform())
    labels = [_pair_label(p) for p in pairs]
    ax.set_yticks(range(len(pairs)), labels, fontsize=7)
    ax.set_ylim(len(pairs) - 0.5, -0.5)
    ax.axvline(0.5, color="black", ls="--", lw=0.9)
    ax.set_xlim(-0.02, 1.02)
    ax.set_xlabel("P(method better on a seed), ties half: final (circle), efficiency (square)")
    ax.set_title("(c) paired verdicts, exact 95% CI", fontsize=10)
    if not pairs:
        ax.text(0.5, 0.5, "no declared pair in this spec", ha="center", va="center", fontsize=8)
    ax.grid(axis="x", alpha=0.25)


PAIR_LABEL_WIDTH = 40
"""Characters of a panel (c) label line that fit beside its axis; a longer pair is wrapped."""


def _pair_label(pair: PairVerdict) -> str:
    """``method > other`` over ``(role)``; a pair too long for one line is wrapped, at the
    ``>`` first, so that its label stays clear of panel (b)."""
    text = f"{pair.method} > {pair.other}"
    if len(text) > PAIR_LABEL_WIDTH:
        text = "\n".join(textwrap.wrap(f"{pair.method} >", 28) + textwrap.wrap(pair.other, 28))
    return f"{text}\n({pair.role})"


def interval_figure(name: str, experiment: Experiment, path: str | Path) -> Path:
    """The interval figure (see :func:`figure`): IQM bands on both accountings and the paired verdicts."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    methods = sorted((m for m, d in experiment.methods.items() if d.iqm is not None), key=order)
    colors = method_colors(methods)
    pairs = len([p for p in experiment.verdicts or () if not p.parents])
    fig, (ax_counted, ax_paper, ax_pairs) = plt.subplots(
        1, 3, figsize=(17, 5), gridspec_kw={"width_ratios": [1.2, 1.2, 1]}
    )
    handles = _iqm_panel(ax_counted, experiment, methods, colors, "counted")
    _iqm_panel(ax_paper, experiment, methods, colors, "paper")
    _verdict_panel(ax_pairs, experiment, colors)
    fig.suptitle(experiment.spec.get("title", name), fontsize=11)
    ncol = 5
    legend_rows = math.ceil(len(handles) / ncol)
    reference = experiment.reference_return
    seeds = list(comparison_of(experiment).seeds)
    caption = (
        f"Compared over seeds {seeds}. Normalised score: (R - R_random) / (R_reference - R_random), R an "
        "undiscounted episode return (mean over the evaluation episodes), R_random the random policy's on the "
        f"same seed, R_reference = {reference:.4g} fixed in the spec. IQM: mean of the middle half of the seeds. "
        "(a) counts every real-target transition a method used, Algorithm 2's U_M rollouts included; (b) its "
        "apprentice's samples only, as the paper counts. (c) Paired over seeds: credited (better) when the "
        "interval lies above 0.5, worse when below; a variant's pairs that are its parent's records are left out."
    )
    caption = "\n".join(textwrap.wrap(caption, width=200))
    # Inches from the bottom: the caption, then the legend above it, then the panels, which
    # grow with panel (c)'s rows (two lines of label each).
    caption_top = 0.1 + 0.15 * (caption.count("\n") + 1)
    block = caption_top + 0.1 + 0.2 * legend_rows + 0.55
    height = block + max(4.6, 0.3 * pairs + 0.8)
    height += 0.3  # the suptitle above the panels' titles
    fig.set_size_inches(17, height)
    fig.subplots_adjust(left=0.05, right=0.9, top=1 - 0.8 / height, bottom=block / height, wspace=0.42)
    fig.legend(handles=handles, loc="lower center", ncol=ncol, fontsize=7.5, frameon=False,
               bbox_to_anchor=(0.5, (caption_top + 0.05) / height))  # fmt: skip
    fig.text(0.05, 0.1 / height, caption, fontsize=7.5, va="bottom", ha="left")
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _label_curve_axes(ax: Any, x_ticks: list[float], xlabel: str, ylabel: str, title: str) -> None:
    """Panel (a)'s log-axis ticks (only those given), labels, title and grid."""
    ax.set_xticks(x_ticks, [compact(b) for b in x_ticks])
    ax.minorticks_off()
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.25)


def _return_figure(name: str, experiment: Experiment, path: str | Path, methods: Sequence[str] | None = None) -> Path:
    """Per-seed returns and samples to threshold (no normalised scores)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    shown = sorted(experiment.methods, key=order) if methods is None else list(methods)
    comparison = comparison_of(experiment, shown)
    results = comparison.methods
    colors = method_colors([r.method for r in results])
    fig, (ax_curve, ax_len) = plt.subplots(1, 2, figsize=(11, 4.0))
    references = [
        v for v in (comparison.random_return, comparison.threshold if comparison.meaningful else None) if v is not None
    ]
    handles, clipped_values = _curve_panel(ax_curve, experiment, comparison, colors, references)

    # Panel (b): per-seed samples to threshold (or final returns without a threshold).
    positions = np.arange(len(results))
    spread = np.linspace(-0.18, 0.18, max(1, len(comparison.seeds))) if len(comparison.seeds) > 1 else [0.0]
    if comparison.meaningful:
        ticks = _threshold_panel(ax_len, experiment, results, colors, spread)
        handles += [
            Line2D([], [], color="black", marker="o", ms=3.5, lw=0, label="(b) one seed"),
            Line2D([], [], color="0.3", lw=3, label="(b) median, 'never' counted as infinite"),
        ]
    else:
        ticks = _final_return_panel(ax_len, comparison, colors, spread, references)
    # Up to five methods fit side by side (labels wrapped); more are slanted.
    many = len(results) > 5
    ax_len.set_xticks(
        positions,
        ticks,
        fontsize=8,
        rotation=30 if many else 0,
        ha="right" if many else "center",
        rotation_mode="anchor" if many else "default",
    )
    ax_len.set_xlim(-0.6, len(results) - 0.4)
    ax_len.grid(axis="y", alpha=0.25)

    fig.suptitle(experiment.spec.get("title", name), fontsize=11)
    _lay_out(fig, handles, ticks, many, _caption(comparison, clipped_values, experiment.reference_return))
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _seed_curves(experiment: Experiment, results: Sequence[MethodResult]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per method, its compared seeds' (target transitions counted, mean return) at each budget."""
    curves = {}
    for r in results:
        data = experiment.methods[r.method]
        rows = data.rows(r.seeds)
        curves[r.method] = (
            data.curve.transitions(verdicts.COUNTED)[rows],
            np.asarray(data.curve.mean_return, dtype=np.float64)[rows],
        )
    return curves


def _curve_panel(
    ax: Any, experiment: Experiment, comparison: Comparison, colors: dict[str, str], references: list[float]
) -> tuple[list[Any], list[float]]:
    """Panel (a): thin per-seed lines, a thick median, references; returns the legend handles
    and the values drawn clipped."""
    from matplotlib.lines import Line2D
    from matplotlib.ticker import FuncFormatter

    curves = _seed_curves(experiment, comparison.methods)
    limits = axis_limits([v for _, y in curves.values() for v in y.ravel()], references)
    handles, clipped, clipped_values = _draw_seed_curves(ax, comparison.methods, curves, colors, limits)
    handles.append(Line2D([], [], color="0.4", lw=0.7, alpha=0.8, label="thin lines: one seed each"))
    if comparison.random_return is not None:
        ax.axhline(comparison.random_return, color="0.45", ls=":", lw=1.2)
        handles.append(
            Line2D([], [], color="0.45", ls=":", lw=1.2, label=f"random policy ({comparison.random_return:.4g})")
        )
    if comparison.meaningful:
        ax.axhline(comparison.threshold, color="black", ls="--", lw=0.9)
        handles.append(Line2D([], [], color="black", ls="--", lw=0.9, label=f"threshold ({comparison.threshold:.4g})"))
    if clipped:
        handles.append(
            Line2D(
                [],
                [],
                color="white",
                marker="v",
                markeredgecolor="black",
                markerfacecolor="0.6",
                ms=6,
                lw=0,
                label=f"beyond the axis, clipped ({clipped} point{'s' * (clipped > 1)})",
            )
        )
    ax.set_ylim(*limits)
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: compact(v)))
    ax.set_xscale("log")
    budgets = sorted({float(b) for counts, _ in curves.values() for b in np.median(counts, axis=0)})
    span = math.log10(max(budgets) / min(budgets)) if budgets else 0.0
    x_ticks = spaced_ticks(budgets, max(0.12, span / 9))
    _label_curve_axes(
        ax,
        x_ticks,
        "target transitions counted (samples, Algorithm 2's rollouts, own data)",
        RETURN_LABEL,
        "(a) return (mean over evaluation episodes)",
    )
    return handles, clipped_values


def _draw_seed_curves(
    ax: Any,
    results: Sequence[MethodResult],
    curves: dict[str, tuple[np.ndarray, np.ndarray]],
    colors: dict[str, str],
    limits: tuple[float, float],
) -> tuple[list[Any], int, list[float]]:
    """Each seed's curve thin, each method's median thick; returns one legend handle per method,
    how many points lie beyond ``limits`` (drawn as triangles on the edge) and their values."""
    from matplotlib.lines import Line2D

    handles: list[Any] = []
    clipped = 0
    clipped_values: list[float] = []
    for r in results:
        counts, returns = curves[r.method]
        color = colors[r.method]
        for seed_counts, seed_returns in zip(counts, returns):
            ax.plot(seed_counts, seed_returns, color=color, lw=0.7, alpha=0.45)
            clipped += mark_clipped(ax, seed_counts, seed_returns, limits, color)
            clipped_values += [v for v in seed_returns if not limits[0] <= v <= limits[1]]
        median = np.median(returns, axis=0)
        style = LINE_STYLES[len(handles) % len(LINE_STYLES)]  # identical curves stay visible
        ax.plot(np.median(counts, axis=0), median, color=color, lw=2.2, ls=style, marker="o", ms=3.5)
        seeds = f"{len(r.seeds)} seed{'s' * (len(r.seeds) > 1)}"
        handles.append(
            Line2D(
                [],
                [],
                color=color,
                lw=2.2,
                ls=style,
                marker="o",
                ms=3.5,
                label=f"{method_label(r.method)}: median of {seeds}",
            )
        )
    return handles, clipped, clipped_values


def _threshold_panel(
    ax: Any, experiment: Experiment, results: Sequence[MethodResult], colors: dict[str, str], spread: Any
) -> list[str]:
    """Panel (b) with a threshold: each seed's target transitions to it, 'never' on a row of its own;
    returns the method tick labels."""
    largest = max(r.largest_budget for r in results)
    never = largest * 3.0  # a row above every budget on the log axis
    for i, r in enumerate(results):
        values = np.asarray([never if math.isinf(v) else v for v in r.samples_to_threshold])
        median = never if math.isinf(r.median_samples) else r.median_samples
        ax.hlines(median, i - 0.3, i + 0.3, color=colors[r.method], lw=3, zorder=2)
        ax.scatter(i + np.asarray(spread), values, color="black", s=12, zorder=3)
    ax.set_yscale("log")
    ax.axhspan(largest * 1.7, never * 1.8, color="0.92", zorder=0)
    methods: dict[str, MethodSummary] = {r.method: experiment.methods[r.method] for r in results}
    smallest = min(min(m.curve.samples) for m in methods.values())
    ax.set_ylim(smallest / 1.6, never * 1.8)
    budget_ticks = sorted({b for m in methods.values() for b in m.curve.samples})
    budget_ticks = spaced_ticks(budget_ticks, max(0.1, math.log10(never / smallest) / 12))
    ax.set_yticks(budget_ticks + [never], [compact(b) for b in budget_ticks] + ["never"])
    ax.minorticks_off()
    ax.set_ylabel("target transitions to threshold")
    ax.set_title("(b) target transitions to threshold", fontsize=10)
    ticks = [f"{_wrap(method_label(r.method))}\n{r.reached}/{len(r.seeds)} reached" for r in results]
    if len(results) > 5:  # slanted below: one line each
        ticks = [f"{method_label(r.method)} ({r.reached}/{len(r.seeds)})" for r in results]
    return ticks


def _final_return_panel(
    ax: Any, comparison: Comparison, colors: dict[str, str], spread: Any, references: list[float]
) -> list[str]:
    """Panel (b) without a meaningful threshold: each seed's final return; returns the method tick labels."""
    from matplotlib.ticker import FuncFormatter

    results = comparison.methods
    finals = [v for r in results for v in r.final_returns]
    final_limits = axis_limits(finals, references)
    for i, r in enumerate(results):
        values = np.asarray(r.final_returns)
        ax.hlines(np.median(values), i - 0.3, i + 0.3, color=colors[r.method], lw=3, zorder=2)
        ax.scatter(i + np.asarray(spread), np.clip(values, *final_limits), color="black", s=12, zorder=3)
        mark_clipped(ax, i + np.asarray(spread), values, final_limits, colors[r.method])
    if comparison.random_return is not None:
        ax.axhline(comparison.random_return, color="0.45", ls=":", lw=1.2)
    ax.set_ylim(*final_limits)
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: compact(v)))
    ax.set_ylabel(f"final {RETURN_LABEL}")
    ax.set_title("(b) final return (no meaningful threshold)", fontsize=10)
    return [_wrap(method_label(r.method)) if len(results) <= 5 else method_label(r.method) for r in results]


def _lay_out(fig: Any, handles: list[Any], ticks: list[str], many: bool, caption: str) -> None:
    """The legend and the caption under the panels, the figure grown to hold them."""
    ncol = min(3, len(handles))
    legend = fig.legend(handles=handles, loc="upper center", ncol=ncol, fontsize=8, frameon=False)
    caption_lines = caption.count("\n") + 1
    legend_rows = math.ceil(len(handles) / ncol)
    # Room under the panels for tick labels, the legend and the caption, in inches.
    tick_lines = max(t.count("\n") + 1 for t in ticks)
    tick_room = 0.3 + 0.16 * tick_lines
    if many:  # slanted at 30 degrees: half the label's width (about 0.075 in a character) goes down
        tick_room = 0.4 + 0.5 * 0.075 * max(len(t) for t in ticks)
    block = tick_room + 0.2 * legend_rows + 0.16 * caption_lines + 0.15
    fig.set_size_inches(11, 3.6 + block)
    height = 3.6 + block
    fig.subplots_adjust(left=0.07, right=0.98, top=1 - 0.55 / height, bottom=block / height, wspace=0.25)
    legend.set_bbox_to_anchor((0.5, (block - tick_room) / height), transform=fig.transFigure)
    fig.text(0.07, 0.1 / height, caption, fontsize=7.5, va="bottom", ha="left")


def _wrap(label: str) -> str:
    return "\n".join(textwrap.wrap(label, width=14)) or label


def _caption(comparison: Comparison, clipped_values: list[float], reference: float | None = None) -> str:
    seeds = f"seeds {list(comparison.seeds)}"
    parts = [f"Compared over {seeds}."]
    if comparison.meaningful:
        rule = (
            f"90% x (reference return {reference:.4g} - random-policy return)"
            if reference is not None
            else f"{THRESHOLD_FRACTION:.0%} x (best method's mean final return - random-policy return)"
        )
        parts.append(
            f"Threshold (dashed) = random-policy return + {rule} = {comparison.threshold:.4g}. (a) Each seed at "
            "the target transitions it counted (samples, Algorithm 2's rollouts, its own data). (b) A seed's "
            "target transitions to threshold: those counted at the smallest budget from which its return stays "
            "at or above the threshold for every larger budget; seeds that never stay there are on the 'never' row."
        )
    else:
        parts.append(
            "No meaningful threshold: no method's mean final return beats the random policy, so the "
            "experiment is judged on final returns; (b) shows each seed's final return."
        )
    if clipped_values:
        parts.append(f"Triangles: values beyond the axis (most extreme {max(clipped_values, key=abs):.3g}).")
    note = seed_note(comparison)
    if note:
        parts.append(note)
    return "\n".join(textwrap.wrap(" ".join(parts), width=170))


def profile(summary: Summary, path: str | Path) -> Path:
    """Performance profiles: the fraction of runs above each normalised score, per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tatl_mj.experiments.results.statistics import performance_profile

    rows = summary.aggregate
    taus = np.linspace(-0.5, 1.5, 201)
    colors = method_colors(sorted(rows))
    fig, ax = plt.subplots(figsize=(10.5, 4.8))
    for i, name in enumerate(sorted(rows, key=lambda m: -(rows[m].estimate.value or -math.inf))):
        style = ("-", "--", ":", "-.")[i % 4]  # identical curves stay visible
        ax.plot(taus, performance_profile(rows[name].scores, taus), style, color=colors[name], lw=1.6,
                label=f"{method_label(name)} ({rows[name].experiments} exp.)")  # fmt: skip
    ax.set_xlabel("normalised final score tau ((R - R_random) / (R_reference - R_random))")
    ax.set_ylabel("fraction of runs with score > tau")
    ax.set_title("Performance profiles over every experiment and seed", fontsize=10)
    ax.grid(alpha=0.25)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


__all__ = ["axis_limits", "figure", "interval_figure", "mark_clipped", "profile"]
