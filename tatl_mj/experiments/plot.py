"""`tatl plot DIR`: the paper's two panels per experiment and a comparison table.

Panel (a): average target return against target samples, mean over seeds
with a 95% Student-t interval, one line per method, the random policy and the
convergence threshold dashed. Panel (b): training length, the target samples
each method needed to reach the threshold (one dot per seed; seeds that never
reached it are drawn at the top, marked "not reached").
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy import stats

from tatl_mj.experiments.records import read_json

COLORS = {"ta-tl": "#d62728", "uma-tl": "#1f77b4", "rl": "#2ca02c"}
LABELS = {"ta-tl": "TA-TL", "uma-tl": "UMA-TL", "rl": "RL (no transfer)"}


def mean_interval(values: np.ndarray, confidence: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
    """Mean over axis 0 and the half-width of its Student-t confidence interval (0 for one seed)."""
    values = np.asarray(values, dtype=np.float64)
    mean = values.mean(axis=0)
    n = values.shape[0]
    if n < 2:
        return mean, np.zeros_like(mean)
    sem = values.std(axis=0, ddof=1) / math.sqrt(n)
    return mean, sem * stats.t.ppf(0.5 + confidence / 2, n - 1)


def _order(method: str) -> tuple[int, str]:
    known = list(LABELS)
    return (known.index(method) if method in known else len(known), method)


def _figure(name: str, experiment: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_curve, ax_len) = plt.subplots(1, 2, figsize=(10, 3.8))
    methods = {m: experiment["methods"][m] for m in sorted(experiment["methods"], key=_order)}
    max_budget = 1
    levels = []
    for m, data in methods.items():
        samples = np.asarray(data["curve"]["samples"])
        max_budget = max(max_budget, samples.max())
        mean, half = mean_interval(np.asarray(data["curve"]["mean_return"]))
        levels.extend(mean)
        color = COLORS.get(m)
        ax_curve.plot(samples, mean, marker="o", ms=3, color=color, label=LABELS.get(m, m))
        ax_curve.fill_between(samples, mean - half, mean + half, color=color, alpha=0.2, lw=0)
    if experiment.get("random_return") is not None:
        ax_curve.axhline(experiment["random_return"], color="grey", ls=":", lw=1, label="random policy")
    if experiment.get("threshold") is not None:
        ax_curve.axhline(experiment["threshold"], color="black", ls="--", lw=0.8, label="threshold")
    # With few seeds the t-interval can be far wider than the spread of the
    # means; keep the means in view (the band is clipped, not hidden).
    levels += [v for v in (experiment.get("random_return"), experiment.get("threshold")) if v is not None]
    low, high = min(levels), max(levels)
    pad = 0.15 * (high - low) if high > low else 1.0
    ax_curve.set_ylim(low - pad, high + pad)
    ax_curve.set_xscale("log")
    ax_curve.set_xlabel("target samples")
    ax_curve.set_ylabel("average return")
    ax_curve.set_title("(a) average reward")
    ax_curve.legend(fontsize=7)

    names = list(methods)
    for i, m in enumerate(names):
        reached = [s for s in methods[m]["samples_to_threshold"] if s is not None]
        missed = sum(s is None for s in methods[m]["samples_to_threshold"])
        if reached:
            ax_len.bar(i, np.median(reached), color=COLORS.get(m), alpha=0.6)
            ax_len.scatter([i] * len(reached), reached, color="black", s=10, zorder=3)
        if missed:
            ax_len.scatter([i] * missed, [max_budget * 1.5] * missed, marker="x", color="black", zorder=3)
            ax_len.annotate(f"{missed} not reached", (i, max_budget * 1.5), fontsize=7, ha="center",
                            xytext=(0, 6), textcoords="offset points")
    ax_len.set_xticks(range(len(names)), [LABELS.get(m, m) for m in names], fontsize=8)
    ax_len.set_yscale("log")
    ax_len.set_ylabel("target samples to threshold")
    ax_len.set_title("(b) training length")
    fig.suptitle(experiment["spec"].get("title", name), fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def median_samples(values: list) -> float:
    """Median samples-to-threshold over seeds, a seed that never reached it counting as infinite."""
    return float(np.median([math.inf if v is None else v for v in values]))


def _fmt(values: list) -> str:
    reached = sum(v is not None for v in values)
    median = median_samples(values)
    text = "not reached" if math.isinf(median) else f"{int(median):,}"
    return f"{text} ({reached}/{len(values)} seeds reached)"


def table(summary: dict) -> str:
    """Markdown: per experiment and method, final return, samples to threshold, ratio to TA-TL."""
    lines = [
        f"Preset `{summary['preset']}`, seeds {summary['seeds']}. Threshold = random return + "
        f"{summary['threshold_fraction']:.0%} of (best method's final return - random return). "
        "Samples to threshold: median over seeds, a seed that never reached it counting as "
        "infinite. Ratio: that median over TA-TL's (> 1: TA-TL needed fewer target samples).",
        "",
    ]
    for name, exp in summary["experiments"].items():
        lines += [f"### {exp['spec'].get('title', name)} (`{name}`)", ""]
        claim = exp["spec"].get("paper_claim")
        if claim:
            lines += [f"Paper: {claim}", ""]
        meaningful = exp["threshold_meaningful"]
        if not meaningful:
            lines += ["**No method beat the random policy here, so samples to threshold are not "
                      "reported.**", ""]
        lines += ["| method | final return (mean ± sd) | target samples to threshold | vs TA-TL |",
                  "|---|---|---|---|"]
        ta = exp["methods"].get("ta-tl")
        ta_median = median_samples(ta["samples_to_threshold"]) if ta else math.inf
        for m in sorted(exp["methods"], key=_order):
            data = exp["methods"][m]
            finals = np.asarray(data["final_return"])
            median = median_samples(data["samples_to_threshold"])
            if not meaningful:
                samples, ratio = "n/a", "n/a"
            else:
                samples = _fmt(data["samples_to_threshold"])
                if m == "ta-tl":
                    ratio = "-"
                elif math.isinf(ta_median) and math.isinf(median):
                    ratio = "neither (median seed) reached it"
                elif math.isinf(ta_median):
                    ratio = "TA-TL (median seed) never reached it"
                elif math.isinf(median):
                    ratio = f"> {max(data['curve']['samples']) / ta_median:.0f}x (median seed never reached it)"
                else:
                    ratio = f"{median / ta_median:.1f}x"
            lines.append(f"| {LABELS.get(m, m)} | {finals.mean():.4g} ± {finals.std():.2g} | {samples} | {ratio} |")
        threshold = "n/a" if exp["threshold"] is None else f"{exp['threshold']:.4g}"
        lines += ["", f"Random policy: {exp['random_return']:.4g}; threshold: {threshold}; target "
                  f"samples used to learn the mapping (shared by TA-TL and UMA-TL, not counted above): "
                  f"{sorted(set(exp['mapping_target_samples']))}.", ""]
    return "\n".join(lines)


def plot(run_dir: str | Path) -> list[Path]:
    """Writes DIR/figures/EXP.png and DIR/results.md; returns the written paths."""
    run_dir = Path(run_dir)
    summary_path = run_dir / "summary.json"
    if not summary_path.exists():
        raise FileNotFoundError(f"{summary_path} not found: run `tatl run ... --out {run_dir}` first")
    summary = read_json(summary_path)
    figures = run_dir / "figures"
    figures.mkdir(exist_ok=True)
    written = []
    for name, experiment in summary["experiments"].items():
        if not experiment["methods"]:
            continue
        path = figures / f"{name}.png"
        _figure(name, experiment, path)
        written.append(path)
    results = run_dir / "results.md"
    results.write_text(table(summary) + "\n")
    written.append(results)
    return written
