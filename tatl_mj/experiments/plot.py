"""`tatl plot DIR`: two panels per experiment and a comparison table (DIR/results.md).

Everything is drawn from the run's summary (:mod:`tatl_mj.experiments.summary`),
so the figure and the table show the same seeds and the same numbers. Where the
experiment declares a reference return (every shipped preset does):

- Panel (a): the IQM over seeds of the normalised score (0: the random policy,
  1: the reference return) against the target transitions counted, with its 95%
  stratified-bootstrap band, and the threshold (dashed).
- Panel (b): the probability that a method beats its source-free ablation (and
  the best baseline) on a seed, on the area under its normalised curve, with its
  95% interval; the verdict beside it.

Without a reference return: (a) per-seed returns (an undiscounted episode sum)
with a thick median and the random policy's return; (b) the target samples each
seed needed to reach the relative threshold ("never" row), or final returns.
A caption under the panels defines what is drawn.

Any number of methods is drawn, each with a colour that depends only on its
name (known methods have fixed ones).
"""

from __future__ import annotations

import math
import textwrap
import zlib
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tatl_mj.experiments.records import read_record
from tatl_mj.experiments.summary import (
    REFERENCE_THRESHOLD,
    THRESHOLD_FRACTION,
    Comparison,
    MethodResult,
    ablation_verdict,
    compare,
    declared_pairs,
    known_kernels,
)

COLORS = {"ta-tl": "#d62728", "uma-tl": "#1f77b4", "rl": "#2ca02c"}
LABELS = {"ta-tl": "TA-TL (paper, Alg. 1)", "uma-tl": "UMA-TL", "rl": "RL (no transfer)"}
# Colours for other methods, picked by a hash of the name (stable across runs);
# none is close to the fixed ones or to the grey/black reference lines.
PALETTE = ("#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22", "#393b79", "#7b4173", "#e7ba52", "#008080")
REFERENCE_METHOD = "ta-tl"  # the table's "vs" column divides by this method's median
LINE_STYLES = ("-", (0, (5, 2)), (0, (1, 1.5)), (0, (6, 2, 1, 2)))  # cycled, so overlapping curves both show
RETURN_LABEL = "return (undiscounted episode sum)"  # the y-axis of every return panel
CLIP_SCALES = 6.0  # values beyond this many robust spreads from the bulk are clipped


def method_label(method: str) -> str:
    return LABELS.get(method, method)


def method_colors(methods: Sequence[str]) -> dict[str, str]:
    """A colour per method: fixed for known names, else by a hash of the name.

    Two methods of one figure never share a colour (a clash moves the later one
    to the next free palette entry).
    """
    taken: set[str] = set()
    colors = {}
    for m in methods:
        if m in COLORS:
            colors[m] = COLORS[m]
            taken.add(COLORS[m])
    for m in methods:
        if m in colors:
            continue
        start = zlib.crc32(m.encode()) % len(PALETTE)
        free = [PALETTE[(start + i) % len(PALETTE)] for i in range(len(PALETTE))]
        colors[m] = next((c for c in free if c not in taken), free[0])
        taken.add(colors[m])
    return colors


def _order(method: str) -> tuple[int, str]:
    known = list(LABELS)
    return (known.index(method) if method in known else len(known), method)


def _fmt_samples(value: float) -> str:
    return "never" if math.isinf(value) else f"{int(value):,}"


def compact(value: float) -> str:
    """A short tick label: 250, 1.5k, 20k, -230k, 1.2M."""
    magnitude = abs(value)
    for scale, suffix in ((1e6, "M"), (1e3, "k")):
        if magnitude >= scale:
            return f"{value / scale:.3g}{suffix}"
    return f"{value:.3g}"


def spaced_ticks(values: Sequence[float], min_gap: float) -> list[float]:
    """``values`` (positive, for a log axis) thinned so neighbours are >= ``min_gap`` decades apart.

    The largest value is always kept (the final budget matters most).
    """
    kept: list[float] = []
    for v in sorted(set(values), reverse=True):
        if not kept or math.log10(kept[-1]) - math.log10(v) >= min_gap:
            kept.append(v)
    return sorted(kept)


# --- Table ------------------------------------------------------------------------


def seed_note(comparison: Comparison) -> str:
    """A sentence saying which seeds are compared and which are left out (empty if none)."""
    if not comparison.seed_sets_differ:
        return ""
    parts = [f"compared over seeds {list(comparison.seeds)}, the ones every method finished"]
    for r in comparison.methods:
        if r.extra_seeds:
            parts.append(f"{method_label(r.method)} also finished {list(r.extra_seeds)} (not compared)")
    for m in comparison.missing:
        parts.append(f"{method_label(m)} finished no seed (not shown)")
    return "Seed sets differ: " + "; ".join(parts) + "."


def _ratio(result: MethodResult, reference: MethodResult | None) -> str:
    if reference is None:
        return "n/a"
    if result.method == reference.method:
        return "-"
    mine, theirs = result.median_samples, reference.median_samples
    if math.isinf(theirs) and math.isinf(mine):
        return "neither (median seed) reached it"
    if math.isinf(theirs):
        return f"{method_label(reference.method)} (median seed) never reached it"
    if math.isinf(mine):
        return f"> {result.largest_budget / theirs:.0f}x (median seed never reached it)"
    return f"{mine / theirs:.1f}x"


def table(summary: dict) -> str:
    """Markdown: per experiment and method, final return, samples to threshold, ratio to TA-TL."""
    lines = [_table_preamble(summary), ""]
    for name, exp in summary["experiments"].items():
        lines += _experiment_section(summary, name, exp)
    return "\n".join(lines)


def _table_preamble(summary: dict) -> str:
    """The paragraph above the tables: what each column and verdict means."""
    return (
        f"Preset `{summary['preset']}`, seeds {summary['seeds']}. Methods are compared only over the "
        "seeds they all finished. Normalised score: (return - random return) / (reference return - random "
        "return), the reference fixed per experiment (under each table). IQM: the mean of the middle half of "
        "the seeds; [95% CI]: stratified percentile bootstrap. Area under the curve: the mean normalised "
        "score over log counted target transitions, from the smallest budget to the largest. Verdicts: "
        "P(method > its source-free ablation) on that area; credited to transfer when its interval lies "
        "above 0.5, worse below, not credited otherwise. Threshold = random return + "
        f"{summary.get('reference_threshold', 0.9):.0%} of (reference return - random return) (without a "
        f"reference: {summary.get('threshold_fraction', THRESHOLD_FRACTION):.0%} of the best method's gap). "
        "Samples to threshold: the real-target transitions a seed counted (its samples, "
        "Algorithm 2's rollouts of the projected source policy, data it drew itself) at the smallest budget "
        "from which its return stays at or above the threshold for every larger budget ('never' if none); "
        f"the median counts 'never' as infinite. vs {method_label(REFERENCE_METHOD)}: that median over "
        f"{method_label(REFERENCE_METHOD)}'s (> 1: {method_label(REFERENCE_METHOD)} needed fewer). Data: "
        "`shared`, the random-policy stream every method shares; `reset`, one-step transitions from states "
        "spread over the target's box (privileged: a simulator reset a robot lacks); `online`, "
        "epsilon-greedy episodes from the task's own starts; `stream`/`source-policy`, the planner's."
        + _kernels_sentence(summary)
    )


def _kernels_sentence(summary: dict) -> str:
    """Which arithmetic kernels computed the records (per-seed returns depend on them), so a
    table copied elsewhere still says what produced it; empty when no record names them."""
    known = known_kernels(summary)
    if not known:
        return ""
    older = sum((summary.get("kernels") or {}).values()) - sum(known.values())
    sets = ", ".join(f"`{k}` ({n:,} records)" for k, n in sorted(known.items()))
    rest = f"; {older:,} older records do not name theirs" if older else ""
    return (
        f" Arithmetic kernels: {sets}{rest}. Per-seed returns depend on them, verdicts should not "
        '(docs/protocol.md, "Across machines").'
    )


def _experiment_section(summary: dict, name: str, exp: dict) -> list[str]:
    """One experiment's heading, method table, verdicts and footnote (the table's lines)."""
    order = sorted(exp["methods"], key=_order)
    # Methods the experiment's own spec lists but that finished no seed are flagged;
    # other experiments' methods are not this one's business.
    listed = list((exp.get("spec") or {}).get("methods") or summary.get("methods", order))
    asked = [m for m in listed if m not in order]
    comparison = compare(exp, order + asked)
    lines = [f"### {exp['spec'].get('title', name)} (`{name}`)", ""]
    claim = exp["spec"].get("paper_claim")
    if claim:
        lines += [f"Paper: {claim}", ""]
    note = seed_note(comparison)
    if note:
        lines += [f"**{note}**", ""]
    if not comparison.methods:
        return lines + ["No method finished any seed.", ""]
    if not comparison.seeds:
        return lines + ["**No seed was finished by every method: nothing to compare.**", ""]
    if not comparison.meaningful:
        lines += [_no_threshold_sentence(comparison), ""]
    stats_on = any("auc" in exp["methods"][r.method] for r in comparison.methods)
    lines += _method_rows(exp, comparison, stats_on)
    lines += _verdict_lines(exp, comparison, stats_on)
    return lines + _experiment_footnote(summary, exp, comparison)


def _method_rows(exp: dict, comparison: Comparison, stats_on: bool) -> list[str]:
    """The markdown table: its header, its rule and one row per compared method."""
    header = "| method | data | final return: mean ± sd (median) | target transitions to threshold: median (per seed) "
    header += f"| vs {method_label(REFERENCE_METHOD)} "
    if stats_on:
        header += "| normalised final score: IQM [95% CI] | area under the curve: IQM [95% CI] "
    lines = [header + "|", "|---" * header.count("|") + "|"]
    reference = comparison.result(REFERENCE_METHOD)
    for r in comparison.methods:
        data = exp["methods"][r.method]
        finals = np.asarray(r.final_returns)
        final = f"{finals.mean():.4g} ± {finals.std():.2g} ({np.median(finals):.4g})"
        if comparison.meaningful:
            per_seed = ", ".join(_fmt_samples(v) for v in r.samples_to_threshold)
            first = min(data["curve"]["samples"])
            left = sum(1 for v in r.samples_to_threshold if math.isfinite(v) and v <= first)
            censored = f"; {left} at the smallest budget (left-censored)" if left else ""
            samples = f"{_fmt_samples(r.median_samples)} ({per_seed}; {r.reached}/{len(r.seeds)} reached{censored})"
            ratio = _ratio(r, reference)
        else:
            samples, ratio = "no meaningful threshold", "n/a"
        row = f"| {method_label(r.method)} | {data['data']} | {final} | {samples} | {ratio} "
        if stats_on:
            row += f"| {interval_text(data.get('final_iqm'))} | {interval_text(data.get('auc'))} "
        lines.append(row + "|")
    return lines


def _verdict_lines(exp: dict, comparison: Comparison, stats_on: bool) -> list[str]:
    """Under the table: against the ablation, survival, placebo, steadiness and the best baseline."""
    lines: list[str] = []
    verdicts = [_pair_sentence(p) for p in exp.get("ablations", [])]
    if not stats_on:
        verdicts = [ablation_verdict(comparison, *pair) for pair in declared_pairs(exp["spec"], "ablation")]
    if any(verdicts):
        lines += ["", "Transfer against its ablation without the source:", ""]
        lines += [f"- {v}" for v in verdicts if v]
    survived = {m: d["survival"] for m, d in exp["methods"].items() if "survival" in d}
    if survived:
        parts = [
            f"{method_label(m)} {v['at_cap']:.2f} ({v['episodes']} episodes, seeds {_seed_range(v.get('seeds'))})"
            for m, v in survived.items()
        ]
        lines += [
            "",
            "Kaplan-Meier survival to the episode cap at the largest budget (episodes pooled over the "
            "compared seeds; only methods with an episode that ended early): " + "; ".join(parts) + ".",
        ]
    if exp.get("placebo"):
        lines += ["", "Transfer against the same method on a placebo (untrained) source:", ""]
        lines += [f"- {_pair_sentence(p, against='its placebo')}" for p in exp["placebo"]]
    steady = {m: d["steadiness"] for m, d in exp["methods"].items() if "steadiness" in d}
    if steady:
        seeds = sorted({_seed_range(d.get("steadiness_seeds")) for d in exp["methods"].values() if "steadiness" in d})
        lines += ["", _steadiness_sentence(steady) + f" Seeds: {'; '.join(seeds)}."]
    best = exp.get("best_baseline")
    if exp.get("vs_best_baseline"):
        lines += ["", f"Against the best baseline here (`{best}`, by area under the curve):", ""]
        lines += [f"- {_pair_sentence(p, against='the best baseline')}" for p in exp["vs_best_baseline"]]
    return lines


def _experiment_footnote(summary: dict, exp: dict, comparison: Comparison) -> list[str]:
    """The line under an experiment: random return, threshold rule and the mapping's samples."""
    threshold = "none" if comparison.threshold is None else f"{comparison.threshold:.4g}"
    mapping = sorted(set(exp.get("mapping_target_samples", [])))
    reference_return = exp.get("reference_return")
    rule = (
        f"reference return {reference_return:.4g} (fixed; threshold at a normalised score of "
        f"{summary.get('reference_threshold', 0.9)})"
        if reference_return is not None
        else "no reference return declared: the threshold is relative to the best method listed"
    )
    return [
        "",
        f"Random policy: {comparison.random_return:.4g}; {rule}; threshold: {threshold}; target "
        f"samples used to learn the mapping (shared by TA-TL and UMA-TL, not counted above): "
        f"{mapping}.",
        "",
    ]


def _seed_range(seeds: Sequence[int] | None) -> str:
    if not seeds:
        return "?"
    seeds = sorted(seeds)
    if seeds == list(range(seeds[0], seeds[-1] + 1)) and len(seeds) > 2:
        return f"{seeds[0]}-{seeds[-1]}"
    return ", ".join(str(s) for s in seeds)


def _steadiness_sentence(steady: dict) -> str:
    """One line: each method's steadiness at the largest budget (IQM over seeds [95% CI])."""
    units = {"roll_rms": ("roll RMS", "deg", 180 / math.pi), "mean_abs_action": ("mean |action|", "", 1.0)}
    parts = []
    for method, measures in sorted(steady.items(), key=lambda kv: _order(kv[0])):
        shown = []
        for name, estimate in measures.items():
            label, unit, scale = units.get(name, (name, "", 1.0))
            scaled = {k: None if estimate[k] is None else estimate[k] * scale for k in ("value", "low", "high")}
            shown.append(f"{label} {interval_text(scaled)}{' ' + unit if unit else ''}")
        parts.append(f"{method_label(method)}: " + ", ".join(shown))
    return (
        "Steadiness at the largest budget, over each episode's steps before it ended (IQM over seeds of the "
        "per-seed mean [95% CI]; these do not saturate where returns reach the cap): " + "; ".join(parts) + "."
    )


def aggregate_table(summary: dict) -> str:
    """Markdown: each method's IQM of normalised final scores over every experiment and seed it ran."""
    rows = summary.get("aggregate") or {}
    if not rows:
        return ""
    lines = [
        "### Across experiments",
        "",
        "Each method's normalised final score (at the largest budget) over every experiment with a "
        "reference return and every seed it ran there: IQM [95% CI] (stratified by experiment). "
        "Methods run on different sets of experiments are not strictly comparable; the count says which. "
        "A mapping variant's rows that are its parent's records (its methods without a source) count once.",
        "",
        "| method | experiments | runs | normalised final score: IQM [95% CI] |",
        "|---|---|---|---|",
    ]
    for name in sorted(rows, key=lambda m: -(rows[m]["value"] or -math.inf)):
        r = rows[name]
        lines.append(f"| {method_label(name)} | {r['experiments']} | {r['runs']} | {interval_text(r)} |")
    return "\n".join(lines) + "\n"


def profile(summary: dict, path: str | Path) -> Path:
    """Performance profiles: the fraction of runs above each normalised score, per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tatl_mj.experiments.statistics import performance_profile

    rows = summary["aggregate"]
    taus = np.linspace(-0.5, 1.5, 201)
    colors = method_colors(sorted(rows))
    fig, ax = plt.subplots(figsize=(10.5, 4.8))
    for i, name in enumerate(sorted(rows, key=lambda m: -(rows[m]["value"] or -math.inf))):
        style = ("-", "--", ":", "-.")[i % 4]  # identical curves stay visible
        ax.plot(taus, performance_profile(rows[name]["scores"], taus), style, color=colors[name], lw=1.6,
                label=f"{method_label(name)} ({rows[name]['experiments']} exp.)")  # fmt: skip
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


def interval_text(estimate: dict | None) -> str:
    if not estimate or estimate.get("value") is None:
        return "n/a"
    if estimate.get("low") is None:
        return f"{estimate['value']:.2f} (no interval)"
    return f"{estimate['value']:.2f} [{estimate['low']:.2f}, {estimate['high']:.2f}]"


VERDICT_WORDS = {
    "credited": "**credited**",
    "worse": "**worse**",
    "not credited": "**not credited**",
}


def _pair_sentence(pair: dict, against: str = "its source-free ablation") -> str:
    """One line: P(method > other) on the area under the curve and at the largest budget, and the verdict."""
    a, b = pair["method"], pair["ablation"]
    meaning = {
        "credited": "the interval lies above 0.5",
        "worse": "the interval lies below 0.5",
        "not credited": "the interval holds 0.5",
    }[pair["verdict"]]
    if pair["probability_of_improvement"].get("low") is None:
        meaning = "too few seeds for an interval"
    if against == "its source-free ablation":
        outcome = f"{VERDICT_WORDS[pair['verdict']]} to transfer"
    elif against == "its placebo":
        outcome = f"{VERDICT_WORDS[pair['verdict']]} to the source's content"
    else:
        outcome = {"credited": "**better**", "worse": "**worse**", "not credited": "**no clear difference**"}[
            pair["verdict"]
        ]
    return (
        f"`{a}` vs `{b}`: P(`{a}` > `{b}`) on the area under the curve "
        f"{interval_text(pair['probability_of_improvement'])}, at the largest budget "
        f"{interval_text(pair['probability_of_improvement_final'])}: {outcome} ({meaning})."
    )


def _no_threshold_sentence(comparison: Comparison) -> str:
    best = method_label(comparison.best_method) if comparison.best_method else "none"
    return (
        f"**No meaningful threshold: no method's mean final return beats the random policy's "
        f"({comparison.random_return:.4g}), so the threshold would lie at or below it. Judged on final "
        f"returns: best {best}.**"
    )


# --- Figures ----------------------------------------------------------------------


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


def _mark_clipped(ax: Any, x: np.ndarray, y: np.ndarray, limits: tuple[float, float], color: str) -> int:
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


def figure(name: str, experiment: dict, path: str | Path, methods: Sequence[str] | None = None) -> Path:
    """Draws one experiment's two panels and caption to ``path``; returns it.

    With normalised scores (a reference return is declared): (a) the IQM of the
    normalised score with its 95% band, (b) the probability of improvement over the
    source-free ablation and over the best baseline. Without: per-seed returns and
    samples to the relative threshold.
    """
    if methods is None and any("iqm" in data for data in experiment["methods"].values()):
        return interval_figure(name, experiment, path)
    return _return_figure(name, experiment, path, methods)


NORMALISED_LABEL = "normalised score (0: random policy, 1: reference return)"


def _iqm_panel(ax: Any, experiment: dict, order: list[str], colors: dict[str, str]) -> list[Any]:
    """IQM of each method's normalised score against its median counted transitions, with the
    95% band; returns the legend handles."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles: list[Any] = []
    drawn: list[float] = []
    lines = []
    for i, method in enumerate(order):
        data = experiment["methods"][method]
        budgets = np.asarray(data["curve"]["samples"], dtype=np.float64)
        counted = np.asarray(data["curve"]["target_transitions"], dtype=np.float64)
        x = np.median(np.where(counted > 0, counted, budgets), axis=0)
        value, low, high = (
            np.array([np.nan if e[k] is None else e[k] for e in data["iqm"]]) for k in ("value", "low", "high")
        )
        lines.append((method, x, value, np.where(np.isnan(low), value, low), np.where(np.isnan(high), value, high)))
        drawn += [*value, *low[np.isfinite(low)], *high[np.isfinite(high)]]
        style = LINE_STYLES[i % len(LINE_STYLES)]  # identical curves stay visible
        handles.append(
            Line2D([], [], color=colors[method], lw=2, ls=style, marker="o", ms=3.5, label=method_label(method))
        )
    limits = axis_limits(drawn, [0.0, 1.0])
    clipped = 0
    for i, (method, x, value, low, high) in enumerate(lines):
        color = colors[method]
        ax.fill_between(x, np.clip(low, *limits), np.clip(high, *limits), color=color, alpha=0.15, lw=0)
        ax.plot(x, np.clip(value, *limits), color=color, lw=2, ls=LINE_STYLES[i % len(LINE_STYLES)], marker="o", ms=3.5)
        clipped += _mark_clipped(ax, x, value, limits, color)
    ax.axhline(0.0, color="0.45", ls=":", lw=1.2)
    ax.axhline(1.0, color="0.45", ls="-.", lw=1.0)
    ax.axhline(REFERENCE_THRESHOLD, color="black", ls="--", lw=0.9)
    handles += [
        Patch(color="0.5", alpha=0.3, label="band: 95% CI (stratified bootstrap over seeds)"),
        Line2D([], [], color="0.45", ls=":", lw=1.2, label="random policy (0)"),
        Line2D([], [], color="0.45", ls="-.", lw=1.0, label="reference return (1)"),
        Line2D([], [], color="black", ls="--", lw=0.9, label=f"threshold ({REFERENCE_THRESHOLD})"),
    ]
    if clipped:
        label = f"IQM beyond the axis ({clipped} point{'s' * (clipped > 1)})"
        handles.append(Line2D([], [], color="white", marker="v", markeredgecolor="black", markerfacecolor="0.6",
                              ms=6, lw=0, label=label))  # fmt: skip
    ax.set_ylim(*limits)
    ax.set_xscale("log")
    ticks = spaced_ticks(sorted({float(v) for _, x, *_ in lines for v in x}), 0.3)
    _label_curve_axes(
        ax,
        ticks,
        "target transitions counted (median over seeds)",
        NORMALISED_LABEL,
        "(a) IQM of the normalised score over seeds, 95% band",
    )
    return handles


def _label_curve_axes(ax: Any, x_ticks: list[float], xlabel: str, ylabel: str, title: str) -> None:
    """Panel (a)'s log-axis ticks (only those given), labels, title and grid."""
    ax.set_xticks(x_ticks, [compact(b) for b in x_ticks])
    ax.minorticks_off()
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.25)


def _improvement_panel(ax: Any, experiment: dict, colors: dict[str, str]) -> None:
    """P(method > other) on the area under the curve, with its interval, for each method against
    its source-free ablation and against the best baseline."""
    pairs = [(p, "its ablation") for p in experiment.get("ablations", [])]
    pairs += [(p, "placebo source") for p in experiment.get("placebo", [])]
    pairs += [(p, "best baseline") for p in experiment.get("vs_best_baseline", [])]
    words = {"credited": "better", "worse": "worse", "not credited": "no clear difference"}
    for row, (pair, kind) in enumerate(pairs):
        estimate = pair["probability_of_improvement"]
        value = estimate["value"]
        low = value if estimate["low"] is None else estimate["low"]
        high = value if estimate["high"] is None else estimate["high"]
        color = colors.get(pair["method"], "black")
        ax.hlines(row, low, high, color=color, lw=5, alpha=0.5)
        ax.plot([value], [row], "o", color=color, markeredgecolor="black", ms=6)
        verdict = words[pair["verdict"]] if kind == "best baseline" else pair["verdict"]
        ax.text(1.02, row, verdict, va="center", fontsize=7.5, transform=ax.get_yaxis_transform())
    labels = [f"{p['method']} > {p['ablation']}\n({kind})" for p, kind in pairs]
    ax.set_yticks(range(len(pairs)), labels, fontsize=7.5)
    ax.set_ylim(len(pairs) - 0.5, -0.5)
    ax.axvline(0.5, color="black", ls="--", lw=0.9)
    ax.set_xlim(0.0, 1.0)
    ax.set_xlabel("P(method beats the other on a seed), area under the normalised curve")
    ax.set_title("(b) probability of improvement, 95% CI", fontsize=10)
    if not pairs:
        ax.text(0.5, 0.5, "no ablation or baseline pair in this spec", ha="center", va="center", fontsize=8)
    ax.grid(axis="x", alpha=0.25)


def interval_figure(name: str, experiment: dict, path: str | Path) -> Path:
    """The interval figure (see :func:`figure`): IQM bands and probabilities of improvement."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    order = sorted((m for m, d in experiment["methods"].items() if "iqm" in d), key=_order)
    colors = method_colors(order)
    pairs = sum(len(experiment.get(k, [])) for k in ("ablations", "placebo", "vs_best_baseline"))
    fig, (ax_curve, ax_pi) = plt.subplots(1, 2, figsize=(12, 4.6), gridspec_kw={"width_ratios": [1.35, 1]})
    handles = _iqm_panel(ax_curve, experiment, order, colors)
    _improvement_panel(ax_pi, experiment, colors)
    fig.suptitle(experiment["spec"].get("title", name), fontsize=11)
    ncol = 4
    legend_rows = math.ceil(len(handles) / ncol)
    reference = experiment.get("reference_return")
    seeds = list(compare(experiment).seeds)
    caption = (
        f"Compared over seeds {seeds}. Normalised score: (R - R_random) / (R_reference - R_random), R an "
        "undiscounted episode return (mean over the evaluation episodes), R_random the random policy's on the "
        f"same seed, R_reference = {reference:.4g} fixed in the spec. (a) IQM: mean of the middle half of the "
        "seeds. (b) Verdict against the ablation: credited when the interval lies above 0.5, worse when below."
    )
    caption = "\n".join(textwrap.wrap(caption, width=180))
    height = 4.6 + 0.22 * legend_rows + 0.5 + 0.05 * max(0, pairs - 6)
    fig.set_size_inches(12, height)
    block = 0.6 + 0.22 * legend_rows + 0.4
    fig.subplots_adjust(left=0.06, right=0.89, top=1 - 0.5 / height, bottom=block / height, wspace=0.55)
    fig.legend(handles=handles, loc="lower center", ncol=ncol, fontsize=7.5, frameon=False,
               bbox_to_anchor=(0.5, 0.42 / height))  # fmt: skip
    fig.text(0.06, 0.08 / height, caption, fontsize=7.5, va="bottom", ha="left")
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _return_figure(name: str, experiment: dict, path: str | Path, methods: Sequence[str] | None = None) -> Path:
    """Per-seed returns and samples to threshold (no normalised scores)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    order = sorted(experiment["methods"], key=_order) if methods is None else list(methods)
    comparison = compare(experiment, order)
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

    fig.suptitle(experiment["spec"].get("title", name), fontsize=11)
    _lay_out(fig, handles, ticks, many, _caption(comparison, clipped_values, experiment.get("reference_return")))
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _seed_curves(experiment: dict, results: Sequence[MethodResult]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per method, its compared seeds' (target transitions counted, mean return) at each budget."""
    curves = {}
    for r in results:
        data = experiment["methods"][r.method]
        rows = [data["seeds"].index(s) for s in r.seeds]
        budgets = np.asarray(data["curve"]["samples"], dtype=np.float64)
        counted = np.asarray(data["curve"]["target_transitions"], dtype=np.float64)
        # Each seed at the target transitions it counted; a reference that counts none at its budget.
        curves[r.method] = (
            np.where(counted[rows] > 0, counted[rows], budgets),
            np.asarray(data["curve"]["mean_return"], dtype=np.float64)[rows],
        )
    return curves


def _curve_panel(
    ax: Any, experiment: dict, comparison: Comparison, colors: dict[str, str], references: list[float]
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
            clipped += _mark_clipped(ax, seed_counts, seed_returns, limits, color)
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
    ax: Any, experiment: dict, results: Sequence[MethodResult], colors: dict[str, str], spread: Any
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
    smallest = min(min(experiment["methods"][r.method]["curve"]["samples"]) for r in results)
    ax.set_ylim(smallest / 1.6, never * 1.8)
    budget_ticks = sorted({b for r in results for b in experiment["methods"][r.method]["curve"]["samples"]})
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
        _mark_clipped(ax, i + np.asarray(spread), values, final_limits, colors[r.method])
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


# --- Sweeps: where transfer is credited ---------------------------------------------


def sweeps(summary: dict) -> dict[str, list[tuple[dict, dict]]]:
    """Sweep name -> its conditions in run order, each as (swept values, experiment)."""
    out: dict[str, list[tuple[dict, dict]]] = {}
    for exp in summary["experiments"].values():
        spec = exp.get("spec") or {}
        if spec.get("condition"):
            out.setdefault(spec.get("streams") or spec["name"], []).append((spec["condition"], exp))
    return out


def _credit_pairs(exp: dict) -> list[tuple[str, dict]]:
    return [("ablation", p) for p in exp.get("ablations", [])] + [("placebo", p) for p in exp.get("placebo", [])]


def credit_table(name: str, cells: list[tuple[dict, dict]]) -> str:
    """Markdown: per condition, P(method > its ablation or placebo) [95% CI] and the verdict."""
    pairs = sorted({(kind, p["method"], p["ablation"]) for _, exp in cells for kind, p in _credit_pairs(exp)})
    params = list(cells[0][0])
    header = "| " + " | ".join(params) + " | " + " | ".join(f"`{m}` > `{a}`" for _, m, a in pairs) + " |"
    lines = [f"### Credit map: `{name}`", "", header, "|---" * (len(params) + len(pairs)) + "|"]
    for condition, exp in cells:
        found = {(kind, p["method"], p["ablation"]): p for kind, p in _credit_pairs(exp)}
        row = [str(condition[k]) for k in params]
        for key in pairs:
            pair = found.get(key)
            estimate = None if pair is None else pair["probability_of_improvement"]
            row.append("n/a" if pair is None else f"{interval_text(estimate)} {pair['verdict']}")
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines + [""])


def _heat_map(
    fig: Any,
    ax: Any,
    cells: list[tuple[dict, dict]],
    params: list[str],
    estimate_of: Callable[[dict], tuple[float, float, float] | None],
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


def credit_map(name: str, cells: list[tuple[dict, dict]], path: str | Path) -> Path:
    """For one sweep: (left) P(method > its ablation or placebo) with its 95% interval over the
    swept parameter (curves; a heat map of the first pair for two parameters); (right) each
    method's normalised final IQM with its band (curves; the first transfer method's for two)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    params = list(cells[0][0])
    fig, (ax_p, ax_s) = plt.subplots(1, 2, figsize=(12, 4.4))
    pairs = sorted({(kind, p["method"], p["ablation"]) for _, exp in cells for kind, p in _credit_pairs(exp)})
    methods = sorted({m for _, exp in cells for m, d in exp["methods"].items() if "final_iqm" in d}, key=_order)
    colors = method_colors(methods)

    def estimate(exp: dict, key: tuple) -> tuple[float, float, float]:
        pair = next((p for kind, p in _credit_pairs(exp) if (kind, p["method"], p["ablation"]) == key), None)
        e = (pair or {}).get("probability_of_improvement") or {}
        value = np.nan if e.get("value") is None else e["value"]
        return value, value if e.get("low") is None else e["low"], value if e.get("high") is None else e["high"]

    def final(exp: dict, method: str) -> tuple[float, float, float]:
        e = exp["methods"].get(method, {}).get("final_iqm") or {}
        value = np.nan if e.get("value") is None else e["value"]
        return value, value if e.get("low") is None else e["low"], value if e.get("high") is None else e["high"]

    if len(params) == 1:
        x = np.arange(len(cells))
        for i, key in enumerate(pairs):
            v, lo, hi = np.array([estimate(exp, key) for _, exp in cells]).T
            color = colors.get(key[1], "black")
            ax_p.errorbar(x + 0.06 * (i - len(pairs) / 2), v, yerr=[v - lo, hi - v], marker="o", capsize=3,
                          ls=LINE_STYLES[i % len(LINE_STYLES)], color=color, label=f"{key[1]} > {key[2]}")  # fmt: skip
        finals = {method: np.array([final(exp, method) for _, exp in cells]).T for method in methods}
        # A baseline's blow-up (scores are unbounded below) must not flatten the others: it is clipped, marked.
        limits = axis_limits([v for f in finals.values() for v in f[0]], keep=(0.0, REFERENCE_THRESHOLD))
        for i, method in enumerate(methods):
            v, lo, hi = finals[method]
            ax_s.plot(x, np.clip(v, *limits), marker="o", color=colors[method], ls=LINE_STYLES[i % len(LINE_STYLES)],
                      label=method)  # fmt: skip
            ax_s.fill_between(x, np.clip(lo, *limits), np.clip(hi, *limits), color=colors[method], alpha=0.15, lw=0)
            _mark_clipped(ax_s, x, v, limits, colors[method])
        ax_s.set_ylim(*limits)
        labels = [str(c[params[0]]) for c, _ in cells]
        for ax in (ax_p, ax_s):
            ax.set_xticks(x, labels)
            ax.set_xlabel(params[0])
            ax.grid(alpha=0.25)
            if ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize=7, frameon=False)
        ax_p.axhline(0.5, color="black", ls="--", lw=0.9)
        ax_p.set_ylim(-0.02, 1.02)
        ax_s.axhline(REFERENCE_THRESHOLD, color="black", ls="--", lw=0.9)
    else:
        focus_method = pairs[0][1] if pairs else (methods[0] if methods else "")
        _heat_map(fig, ax_p, cells, params, lambda exp: estimate(exp, pairs[0]) if pairs else None, "RdBu", (0, 1))
        _heat_map(fig, ax_s, cells, params, lambda exp: final(exp, focus_method), "viridis", (None, None))
    pair_text = f"{pairs[0][1]} > {pairs[0][2]}" if pairs and len(params) == 2 else "method > its ablation or placebo"
    ax_p.set_title(f"(a) P({pair_text}) on the area under the curve, 95% CI", fontsize=10)
    focus = f" of {pairs[0][1] if pairs else methods[0]}" if methods and len(params) == 2 else ""
    spread = "95% CI" if len(params) == 2 else "95% band"
    ax_s.set_title(f"(b) normalised final score{focus}: IQM over seeds, {spread}", fontsize=10)
    fig.suptitle(f"Where transfer is credited: {name}", fontsize=11)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot(run_dir: str | Path) -> list[Path]:
    """Writes DIR/figures/EXP.png and DIR/results.md; returns the written paths."""
    run_dir = Path(run_dir)
    summary_path = run_dir / "summary.json"
    if not summary_path.exists():
        raise FileNotFoundError(f"{summary_path} not found: run `tatl run ... --out {run_dir}` first")
    summary = read_record(summary_path)
    figures = run_dir / "figures"
    figures.mkdir(exist_ok=True)
    written = []
    for name, experiment in summary["experiments"].items():
        if not compare(experiment).seeds:
            continue
        written.append(figure(name, experiment, figures / f"{name}.png"))
    if summary.get("aggregate"):
        written.append(profile(summary, figures / "performance_profile.png"))
    credit = []
    for name, cells in sweeps(summary).items():
        written.append(credit_map(name, cells, figures / f"credit_{name}.png"))
        credit.append(credit_table(name, cells))
    results = run_dir / "results.md"
    results.write_text(table(summary) + "\n" + aggregate_table(summary) + "\n" + "\n".join(credit))
    written.append(results)
    return written
