"""The markdown a run's summary reads as: results.md's tables, the sweeps' credit tables, and the
headline tables the README and docs/results-paper.md print (``paper_table``, ``verdict_table``).

Everything is read from summary.json (:mod:`tatl_mj.experiments.results.summary`): a table and the
figures of the same run show the same seeds and numbers. The definitions behind the columns
live once, in docs/protocol.md; :func:`table` opens with a short key.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from tatl_mj.experiments.report.style import interval_text, method_label, order, samples_text, seed_range
from tatl_mj.experiments.results import statistics as stats
from tatl_mj.experiments.results import verdicts
from tatl_mj.experiments.results.summary import (
    REFERENCE_THRESHOLD,
    THRESHOLD_FRACTION,
    Comparison,
    ablation_sentences,
    compare,
    known_kernels,
)

PAPER_METHODS = ("ta-tl", "uma-tl", "rl")
"""The paper's three methods, on its protocol (the shared random-policy stream)."""

VERDICT_WORDS = {"credited": "**credited**", "worse": "**worse**", "not credited": "not credited"}
BASELINE_WORDS = {"credited": "**better**", "worse": "**worse**", "not credited": "no clear difference"}
ROLE_WORDS = {verdicts.ABLATION: "source-free", verdicts.PLACEBO: "placebo", verdicts.BEST_BASELINE: "best baseline"}
HOLM_MARK = "†"


# --- results.md -----------------------------------------------------------------------


def table(summary: dict) -> str:
    """results.md's experiment sections: per experiment its methods, then its verdicts."""
    lines = [_preamble(summary), ""]
    for name, exp in summary["experiments"].items():
        lines += _experiment_section(summary, name, exp)
    return "\n".join(lines)


def _preamble(summary: dict) -> str:
    """The key above the tables (the definitions: docs/protocol.md)."""
    return (
        f"Preset `{summary['preset']}`, seeds {summary['seeds']}; verdict rule version "
        f"{summary.get('verdict_rule_version', 1)} (docs/protocol.md defines every column). Methods are compared "
        "over the seeds they all finished, seed by seed (the seeds of an experiment share their source policy, "
        "target samples and evaluation starts). Normalised score: 0 the random policy, 1 the experiment's "
        "reference return. *counted*: every real-target transition a method used, Algorithm 2's rollouts of the "
        "projected source policy included; *paper's*: the apprentice's samples only, as the paper counts. "
        "Efficiency: the mean normalised score over log counted transitions, from the smallest budget to the "
        "largest, 0 before a method's first policy, scores floored at -1. Verdicts answer two questions per pair, "
        "*final* (at the largest budget) and *efficiency*: P = (seeds better + ties / 2) / seeds, with its exact "
        "95% interval; **credited** / **better** when it lies above 0.5, **worse** below, not credited / no clear "
        f"difference otherwise; {HOLM_MARK}: the verdict also holds under Holm's correction within the experiment's "
        f"family. Threshold: a normalised score of {summary.get('reference_threshold', REFERENCE_THRESHOLD)} "
        f"(without a reference: {summary.get('threshold_fraction', THRESHOLD_FRACTION):.0%} of the best method's gap); "
        "transitions to it: those counted at the smallest budget from which a seed stays at or above it. Data: "
        "`shared` (the random-policy stream every method shares), `reset` (privileged: one-step transitions from "
        "states spread over the target's box), `online` (epsilon-greedy episodes), `stream`/`source-policy` "
        "(the grid planner's)." + _kernels_sentence(summary)
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


def _experiment_section(summary: dict, name: str, exp: dict) -> list[str]:
    """One experiment's heading, verdicts, method table and footnote."""
    methods = sorted(exp["methods"], key=order)
    # Methods the experiment's own spec lists but that finished no seed are flagged;
    # other experiments' methods are not this one's business.
    listed = list((exp.get("spec") or {}).get("methods") or summary.get("methods", methods))
    comparison = compare(exp, methods + [m for m in listed if m not in methods])
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
    # The verdicts first, then the methods' numbers they rest on.
    if "verdicts" in exp:
        lines += _verdict_rows(exp) + [""]
    elif sentences := ablation_sentences(exp, comparison):  # no reference return: a sentence per ablation
        lines += ["Transfer against its ablation without the source:", ""]
        lines += [f"- {v}" for v in sentences] + [""]
    lines += _method_rows(exp, comparison)
    lines += _capped_lines(exp)
    return lines + _footnote(summary, exp, comparison)


def _method_rows(exp: dict, comparison: Comparison) -> list[str]:
    """The method table: one row per compared method."""
    stats_on = any("efficiency" in exp["methods"][r.method] for r in comparison.methods)
    header = "| method | data | final return: mean ± sd (median) | transitions to threshold, counted: median (seeds) "
    header += "| paper's accounting: median "
    if stats_on:
        header += (
            "| first policy after, counted / paper's | normalised final score: IQM [95% CI] "
            "| efficiency: IQM [95% CI] | efficiency, paper's accounting "
        )
    lines = [header + "|", "|---" * header.count("|") + "|"]
    for r in comparison.methods:
        data = exp["methods"][r.method]
        finals = np.asarray(r.final_returns)
        final = f"{finals.mean():.4g} ± {finals.std():.2g} ({np.median(finals):.4g})"
        if comparison.meaningful:
            first = min(data["curve"]["samples"])
            left = sum(1 for v in r.samples_to_threshold if math.isfinite(v) and v <= first)
            censored = f", {left} at the smallest budget" if left else ""
            counted = f"{samples_text(r.median_samples)} ({r.reached}/{len(r.seeds)} reached{censored})"
            paper = samples_text(r.median_samples_paper)
        else:
            counted, paper = "no meaningful threshold", "n/a"
        row = f"| {method_label(r.method)} | {data['data']} | {final} | {counted} | {paper} "
        if stats_on:
            first_policy = data.get("first_policy") or {}
            row += (
                f"| {samples_text(first_policy.get('counted'))} / {samples_text(first_policy.get('paper'))} "
                f"| {interval_text(data.get('final_iqm'))} | {interval_text(data.get('efficiency'))} "
                f"| {interval_text(data.get('efficiency_paper'))} "
            )
        lines.append(row + "|")
    return lines


def answer_text(answer: dict | None, words: dict[str, str] = VERDICT_WORDS) -> tuple[str, str]:
    """``(P [CI] (better/tied/worse), verdict)`` of one question of a pair, "-" where not asked."""
    if not answer:
        return "-", "-"
    seeds = answer["seeds"]
    mark = HOLM_MARK if answer.get("holm") else ""
    return (
        f"{interval_text(answer['probability'])} ({seeds['better']}/{seeds['tied']}/{seeds['worse']})",
        words[answer["verdict"]] + mark,
    )


def _verdict_rows(exp: dict) -> list[str]:
    """The verdicts of the declared pairs, both questions each."""
    pairs = exp.get("verdicts") or []
    if not pairs:
        return ["No declared pair has both of its methods here: no verdict."]
    families = exp.get("families") or {}
    lines = [
        f"Verdicts (P = (better + tied / 2) / seeds, seeds better/tied/worse in brackets; the family holds "
        f"{families.get('final', '?')} pairs asking *final* and {families.get('efficiency', '?')} asking "
        f"*efficiency*; intervals unadjusted, {HOLM_MARK} where Holm's correction keeps the verdict):",
        "",
        "| method | against | final: P [95% CI] | median difference [95% CI] | verdict "
        "| efficiency: P [95% CI] | verdict | efficiency, paper's accounting: verdict |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for pair in pairs:
        final_p, final_v, efficiency_p, efficiency_v, paper_v = _answer_cells(pair)
        difference = (
            interval_text((pair.get("final") or {}).get("median_difference"), "+.2f") if "final" in pair else "-"
        )
        against = f"`{pair['other']}` ({ROLE_WORDS[pair['role']]})"
        if pair.get("parents"):
            against += f" (the parent `{exp['spec'].get('streams')}`'s records)"
        lines.append(
            f"| `{pair['method']}` | {against} | {final_p} | {difference} | {final_v} "
            f"| {efficiency_p} | {efficiency_v} | {paper_v} |"
        )
    return lines


def _capped_lines(exp: dict) -> list[str]:
    """Survival to the episode cap and steadiness, where the target has them."""
    lines: list[str] = []
    survived = {m: d["survival"] for m, d in exp["methods"].items() if "survival" in d}
    if survived:
        parts = [
            f"{method_label(m)} {v['at_cap']:.2f} ({v['episodes']} episodes, seeds {seed_range(v.get('seeds'))})"
            for m, v in survived.items()
        ]
        lines += [
            "",
            "Kaplan-Meier survival to the episode cap at the largest budget (episodes pooled over the "
            "compared seeds; only methods with an episode that ended early): " + "; ".join(parts) + ".",
        ]
    steady = {m: d["steadiness"] for m, d in exp["methods"].items() if "steadiness" in d}
    if steady:
        seeds = sorted({seed_range(d.get("steadiness_seeds")) for d in exp["methods"].values() if "steadiness" in d})
        lines += ["", _steadiness_sentence(steady) + f" Seeds: {'; '.join(seeds)}."]
    return lines


def _footnote(summary: dict, exp: dict, comparison: Comparison) -> list[str]:
    """The line under an experiment: random return, threshold rule, the area's range, the mapping's samples."""
    threshold = "none" if comparison.threshold is None else f"{comparison.threshold:.4g}"
    mapping = sorted(set(exp.get("mapping_target_samples", [])))
    reference_return = exp.get("reference_return")
    rule = (
        f"reference return {reference_return:.4g} (fixed; threshold at a normalised score of "
        f"{summary.get('reference_threshold', REFERENCE_THRESHOLD)})"
        if reference_return is not None
        else "no reference return declared: the threshold is relative to the best method listed"
    )
    span = exp.get("efficiency_range")
    area = f"; efficiency over {span[0]:,.0f} to {span[1]:,.0f} transitions" if span else ""
    return [
        "",
        f"Random policy: {comparison.random_return:.4g}; {rule}; threshold: {threshold}{area}; target samples "
        f"used to learn the mapping (shared by TA-TL and UMA-TL, not counted above): {mapping}.",
        "",
    ]


def _steadiness_sentence(steady: dict) -> str:
    """One line: each method's steadiness at the largest budget (IQM over seeds [95% CI])."""
    units = {"roll_rms": ("roll RMS", "deg", 180 / math.pi), "mean_abs_action": ("mean |action|", "", 1.0)}
    parts = []
    for method, measures in sorted(steady.items(), key=lambda kv: order(kv[0])):
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


def _no_threshold_sentence(comparison: Comparison) -> str:
    best = method_label(comparison.best_method) if comparison.best_method else "none"
    return (
        f"**No meaningful threshold: no method's mean final return beats the random policy's "
        f"({comparison.random_return:.4g}), so the threshold would lie at or below it. Judged on final "
        f"returns: best {best}.**"
    )


def aggregate_table(summary: dict) -> str:
    """Each method's IQM of normalised final scores over every experiment and seed it ran."""
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


def credit_table(name: str, cells: list[tuple[dict, dict]]) -> str:
    """Per sweep condition, each transfer method against its ablation and placebo, both questions."""
    credit = (verdicts.ABLATION, verdicts.PLACEBO)
    keys = sorted(
        {(v["method"], v["other"]) for _, exp in cells for v in exp.get("verdicts", []) if v["role"] in credit}
    )
    params = list(cells[0][0])
    header = "| " + " | ".join(params) + " | " + " | ".join(f"`{m}` > `{a}`: final; efficiency" for m, a in keys) + " |"
    lines = [f"### Credit map: `{name}`", "", header, "|---" * (len(params) + len(keys)) + "|"]
    for condition, exp in cells:
        found = {(v["method"], v["other"]): v for v in exp.get("verdicts", [])}
        row = [str(condition[k]) for k in params]
        for key in keys:
            pair = found.get(key)
            if pair is None:
                row.append("n/a")
                continue
            parts = [" ".join(answer_text(pair.get(q))) for q in verdicts.QUESTIONS]
            row.append("; ".join(parts))
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines + [""])


# --- the headline tables --------------------------------------------------------------


def _answer_cells(pair: dict) -> tuple[str, str, str, str, str]:
    """A pair's final P and verdict, efficiency P and verdict, and the paper-accounting verdict
    (without the Holm mark: that question is not in the family)."""
    words = BASELINE_WORDS if pair["role"] == verdicts.BEST_BASELINE else VERDICT_WORDS
    final_p, final_v = answer_text(pair.get("final"), words)
    efficiency_p, efficiency_v = answer_text(pair.get("efficiency"), words)
    paper_v = answer_text(pair.get("efficiency_paper"), words)[1].rstrip(HOLM_MARK)
    return final_p, final_v, efficiency_p, efficiency_v, paper_v


def verdict_table(
    summary: dict,
    prefix: str = "",
    roles: Sequence[str] = (verdicts.ABLATION, verdicts.PLACEBO),
    methods: Sequence[str] | None = None,
    credited_only: bool = False,
) -> str:
    """One row per declared pair of the given roles whose method starts with ``prefix`` (or is one of
    ``methods``), both questions: the README's credit tables (a variant's pairs that are its
    parent's are left out). ``credited_only``: only pairs credited (or better) on either question."""
    lines = [
        "| experiment | method | against | final: P [95% CI] | verdict | efficiency: P [95% CI] | verdict "
        "| efficiency, paper's accounting | normalised final score, method / against |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for exp in summary["experiments"].values():
        title = exp["spec"].get("title", exp["spec"]["name"])
        for pair in exp.get("verdicts", []):
            if pair["role"] not in roles or pair.get("parents") or not pair["method"].startswith(prefix):
                continue
            if methods is not None and pair["method"] not in methods:
                continue
            if credited_only and not any(
                (pair.get(q) or {}).get("verdict") == stats.CREDITED for q in verdicts.QUESTIONS
            ):
                continue
            final_p, final_v, efficiency_p, efficiency_v, paper_v = _answer_cells(pair)
            mine, theirs = (exp["methods"][m].get("final_iqm") for m in (pair["method"], pair["other"]))
            lines.append(
                f"| {title} | `{pair['method']}` | `{pair['other']}` ({ROLE_WORDS[pair['role']]}) | {final_p} "
                f"| {final_v} | {efficiency_p} | {efficiency_v} | {paper_v} "
                f"| {interval_text(mine)} / {interval_text(theirs)} |"
            )
    return "\n".join(lines)


def reproduced(to_threshold: dict[str, float | None]) -> str:
    """The paper's central claim, TA-TL reaches the threshold with fewer samples than UMA-TL and
    RL, read from the median samples to threshold on the paper's protocol and accounting:
    ``yes`` fewer than both, ``partly`` fewer than one, ``no`` otherwise (TA-TL never reaching
    it included)."""
    mine = to_threshold.get("ta-tl")
    if mine is None or math.isinf(mine):
        return "no"
    others = [to_threshold.get(m) for m in ("uma-tl", "rl")]
    fewer = sum(1 for v in others if v is None or math.isinf(v) or mine < v)
    return {2: "yes", 1: "partly"}.get(fewer, "no")


def paper_table(summary: dict) -> str:
    """The paper's own comparison first: per experiment the paper's claim and numbers, ours on the
    paper's protocol and accounting (the shared random-policy stream, apprentice samples only),
    ours counted (Algorithm 2's rollouts included), and whether the claim is reproduced."""
    lines = [
        "| experiment | the paper | the paper's numbers | here, paper's accounting: median transitions to "
        "threshold, TA-TL / UMA-TL / RL | here, counted: TA-TL | normalised final score (IQM), TA-TL / UMA-TL / RL "
        "| reproduced |",
        "|---|---|---|---|---|---|---|",
    ]
    for exp in summary["experiments"].values():
        spec = exp["spec"]
        paper = spec.get("paper") or {}
        if not paper:
            continue  # a variant or sweep of ours: no claim of the paper's to compare
        comparison = compare(exp, [m for m in PAPER_METHODS if m in exp["methods"]])
        medians = {r.method: r.median_samples_paper for r in comparison.methods if comparison.meaningful}
        counted = comparison.result("ta-tl")
        finals = " / ".join(interval_text((exp["methods"].get(m) or {}).get("final_iqm")) for m in PAPER_METHODS)
        lines.append(
            f"| {spec.get('title', spec['name'])} | {paper.get('section', '')} | {paper.get('numbers', '')} "
            f"| {' / '.join(samples_text(medians.get(m)) for m in PAPER_METHODS)} "
            f"| {samples_text(counted.median_samples if counted else None)} | {finals} | {reproduced(medians)} |"
        )
    return "\n".join(lines)


__all__ = [
    "PAPER_METHODS",
    "aggregate_table",
    "answer_text",
    "credit_table",
    "paper_table",
    "reproduced",
    "seed_note",
    "table",
    "verdict_table",
]
