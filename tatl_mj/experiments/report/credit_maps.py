"""The sweeps' credit maps: where along a target condition transfer is credited (``tatl plot``
draws one per ``[sweep]`` spec; ``tables.credit_table`` is its table)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from tatl_mj.experiments.report import privileges
from tatl_mj.experiments.report.figures import LINE_STYLES, axis_limits, mark_clipped
from tatl_mj.experiments.report.style import method_colors, order
from tatl_mj.experiments.results import verdicts
from tatl_mj.experiments.results.comparison import REFERENCE_THRESHOLD
from tatl_mj.experiments.results.summary_data import Experiment, Interval, PairVerdict, Summary


def sweeps(summary: Summary) -> dict[str, list[tuple[dict, Experiment]]]:
    """Sweep name -> its conditions in run order, each as (swept values, experiment)."""
    out: dict[str, list[tuple[dict, Experiment]]] = {}
    for exp in summary.experiments.values():
        spec = exp.spec
        if spec.get("condition"):
            out.setdefault(spec.get("streams") or spec["name"], []).append((spec["condition"], exp))
    return out


def _credit_pairs(exp: Experiment) -> list[PairVerdict]:
    """The experiment's pairs that credit transfer: against the ablation and the placebo."""
    return [v for v in exp.verdicts or () if v.role in (verdicts.ABLATION, verdicts.PLACEBO)]


def _heat_map(
    fig: Any,
    ax: Any,
    cells: list[tuple[dict, Experiment]],
    params: list[str],
    estimate_of: Callable[[Experiment], tuple[float, float, float] | None],
    cmap: str,
    limits: tuple[float | None, float | None],
) -> None:
    """One estimate per condition of a two-parameter sweep: colour by its value, its
    interval written in the cell."""
    first, second = ([c[k] for c, _ in cells] for k in params)
    rows, cols = sorted(set(first), key=first.index), sorted(set(second), key=second.index)
    grid = np.full((len(rows), len(cols)), np.nan)
    text = {}
    for condition, exp in cells:
        r, c = rows.index(condition[params[0]]), cols.index(condition[params[1]])
        found = estimate_of(exp)
        if found is not None and not np.isnan(found[0]):
            grid[r, c] = found[0]
            text[r, c] = f"{found[0]:.2f}\n[{found[1]:.2f}, {found[2]:.2f}]"
    image = ax.imshow(grid, cmap=cmap, vmin=limits[0], vmax=limits[1], aspect="auto")
    for (r, c), value in np.ndenumerate(grid):
        # White on the darkest colours, black elsewhere, so every cell stays readable.
        shade = image.cmap(image.norm(value)) if np.isfinite(value) else (1.0, 1.0, 1.0, 1.0)
        colour = "white" if 0.299 * shade[0] + 0.587 * shade[1] + 0.114 * shade[2] < 0.45 else "black"
        ax.text(c, r, text.get((r, c), "n/a"), ha="center", va="center", fontsize=8, color=colour)
    ax.set_xticks(range(len(cols)), [str(v) for v in cols])
    ax.set_yticks(range(len(rows)), [str(v) for v in rows])
    ax.set_xlabel(params[1])
    ax.set_ylabel(params[0])
    fig.colorbar(image, ax=ax)


def _pair_label(key: tuple, marked: dict[str, frozenset[str]]) -> str:
    """``method > other``; a privileged comparator's pair is information (privileges.credits), said here."""
    held = privileges.no_more_resources(marked, key[1], key[2])
    return f"{key[1]} > {key[2]}" + ("" if held else " [privileged]")


def credit_map(name: str, cells: list[tuple[dict, Experiment]], path: str | Path) -> Path:
    """For one sweep: (left) P(method > its ablation or placebo) with its 95% interval over the
    swept parameter (curves; a heat map of the first pair for two parameters); (right) each
    method's normalised final IQM with its band (curves; the first transfer method's for two)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    params = list(cells[0][0])
    pairs = sorted({(p.role, p.method, p.other) for _, exp in cells for p in _credit_pairs(exp)})
    # Room below the panels for (a)'s legend, two entries a pair, two columns (one parameter only).
    legend_rows = len(pairs) if len(params) == 1 else 0
    fig, (ax_p, ax_s) = plt.subplots(1, 2, figsize=(12, 4.4 + 0.16 * legend_rows))
    marked = privileges.privileged(cells[0][1].spec_methods)

    methods = sorted({m for _, exp in cells for m, d in exp.methods.items() if d.final_iqm is not None}, key=order)
    colors = method_colors(methods)
    missing = Interval(None, None, None)

    def estimate(exp: Experiment, key: tuple, question: str = verdicts.EFFICIENCY) -> tuple[float, float, float]:
        pair = next((p for p in _credit_pairs(exp) if (p.role, p.method, p.other) == key), None)
        answer = None if pair is None else pair.answer(question)
        return (missing if answer is None else answer.probability).bounds()

    def final(exp: Experiment, method: str) -> tuple[float, float, float]:
        data = exp.methods.get(method)
        return (missing if data is None or data.final_iqm is None else data.final_iqm).bounds()

    if len(params) == 1:
        x = np.arange(len(cells))
        for i, key in enumerate(pairs):
            color = colors.get(key[1], "black")
            for question, marker, shift in ((verdicts.FINAL, "o", -0.04), (verdicts.EFFICIENCY, "s", 0.04)):
                v, lo, hi = np.array([estimate(exp, key, question) for _, exp in cells]).T
                ax_p.errorbar(x + 0.1 * (i - len(pairs) / 2) + shift, v, yerr=[v - lo, hi - v], marker=marker,
                              capsize=3, ls=LINE_STYLES[i % len(LINE_STYLES)], color=color,
                              label=f"{_pair_label(key, marked)} ({question})")  # fmt: skip
        finals = {method: np.array([final(exp, method) for _, exp in cells]).T for method in methods}
        # A baseline's blow-up (scores are unbounded below) must not flatten the others: it is clipped, marked.
        limits = axis_limits([v for f in finals.values() for v in f[0]], keep=(0.0, REFERENCE_THRESHOLD))
        for i, method in enumerate(methods):
            v, lo, hi = finals[method]
            ax_s.plot(x, np.clip(v, *limits), marker="o", color=colors[method], ls=LINE_STYLES[i % len(LINE_STYLES)],
                      label=method)  # fmt: skip
            ax_s.fill_between(x, np.clip(lo, *limits), np.clip(hi, *limits), color=colors[method], alpha=0.15, lw=0)
            mark_clipped(ax_s, x, v, limits, colors[method])
        ax_s.set_ylim(*limits)
        labels = [str(c[params[0]]) for c, _ in cells]
        for ax in (ax_p, ax_s):
            ax.set_xticks(x, labels)
            ax.set_xlabel(params[0])
            ax.grid(alpha=0.25)
        # (a)'s pairs below its panel, where they cover no interval; (b)'s few methods inside.
        if ax_p.get_legend_handles_labels()[0]:
            ax_p.legend(fontsize=7, frameon=False, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2)
        if ax_s.get_legend_handles_labels()[0]:
            ax_s.legend(fontsize=7, frameon=False)
        ax_p.axhline(0.5, color="black", ls="--", lw=0.9)
        ax_p.set_ylim(-0.02, 1.02)
        ax_s.axhline(REFERENCE_THRESHOLD, color="black", ls="--", lw=0.9)
    else:
        focus_method = pairs[0][1] if pairs else (methods[0] if methods else "")
        _heat_map(fig, ax_p, cells, params, lambda exp: estimate(exp, pairs[0]) if pairs else None, "RdBu", (0, 1))
        _heat_map(fig, ax_s, cells, params, lambda exp: final(exp, focus_method), "viridis", (None, None))
    pair_text = _pair_label(pairs[0], marked) if pairs and len(params) == 2 else "method > its ablation or placebo"
    on = "efficiency" if len(params) == 2 else "final (circles), efficiency (squares)"
    ax_p.set_title(f"(a) paired P({pair_text}) on a seed,\n{on}, 95% CI", fontsize=10)
    focus = f" of {pairs[0][1] if pairs else methods[0]}" if methods and len(params) == 2 else ""
    spread = "95% CI" if len(params) == 2 else "95% band"
    ax_s.set_title(f"(b) normalised final score{focus}: IQM over seeds, {spread}", fontsize=10)
    fig.suptitle(f"Where transfer is credited: {name}", fontsize=11)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


__all__ = ["credit_map", "sweeps"]
