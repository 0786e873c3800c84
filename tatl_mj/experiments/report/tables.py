"""The markdown a run's summary reads as: results.md's tables, the sweeps' credit tables, and the
headline tables the README and docs/results-paper.md print (``paper_table``, ``verdict_table``).

Everything is read from summary.json (:mod:`tatl_mj.experiments.results.summary_data`): a table and the
figures of the same run show the same seeds and numbers. The definitions behind the columns
live once, in docs/protocol.md; :func:`table` opens with a short key.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from tatl_mj.experiments.report.privileges import (
    INFORMATION,
    MORE_ACTIONS,
    NOT_CREDIT,
    against,
    credits,
    method_cell,
    more_actions,
    no_more_resources,
    ordered,
    privileged,
)
from tatl_mj.experiments.report.style import interval_text, method_label, order, samples_text, seed_range
from tatl_mj.experiments.results import verdicts
from tatl_mj.experiments.results.comparison import Comparison, comparison_of
from tatl_mj.experiments.results.summary_data import Answer, Experiment, Interval, PairVerdict, Summary

PAPER_METHODS = ("ta-tl", "uma-tl", "rl")
"""The paper's three methods, on its protocol (the shared random-policy stream)."""

READINGS = ("ta-tl", "ta-tl-continuous")
"""The paper's two readings of TA-TL's action, of equal standing, each a row of the headline tables
(``paper_table``, the README's credit table): ``ta-tl`` snaps it to the target's three discrete
actions, the set every comparator chooses from; ``ta-tl-continuous`` clips the torque at the
actuator's limit, so it has more actions than its comparators (docs/protocol.md, "Departures made
equal"). A credit headline, a sentence or count saying where transfer is credited, reads
``CREDIT_READING``, the same-actions row."""
CREDIT_READING = READINGS[0]
READING_LABELS = {"ta-tl": "three target actions", "ta-tl-continuous": "torque clipped at the limit"}

VERDICT_WORDS = verdicts.words(verdicts.ABLATION, marked=True)
BASELINE_WORDS = verdicts.words(verdicts.BEST_BASELINE, marked=True)
HOLM_MARK = "†"


# --- results.md -----------------------------------------------------------------------


def table(summary: Summary) -> str:
    """results.md's experiment sections: per experiment its methods, then its verdicts."""
    lines = [_preamble(summary), ""]
    for exp in summary.experiments.values():
        lines += _experiment_section(summary, exp)
    return "\n".join(lines)


def _preamble(summary: Summary) -> str:
    """The key above the tables (the definitions: docs/protocol.md)."""
    return (
        f"Preset `{summary.preset}`, seeds {summary.seeds}; verdict rule version "
        f"{summary.verdict_rule_version} (docs/protocol.md defines every column). Methods are compared "
        "over the seeds they all finished, seed by seed (the seeds of an experiment share their source policy, "
        "target samples and evaluation starts). Normalised score: 0 the random policy, 1 the experiment's "
        "reference return. *counted*: every real-target transition a method used, Algorithm 2's rollouts of the "
        "projected source policy included; *paper's*: the apprentice's samples only, as the paper counts. "
        "Efficiency: the mean normalised score over log counted transitions, from the smallest budget to the "
        "largest, 0 before a method's first policy, scores floored at -1. Verdicts answer two questions per pair, "
        "*final* (at the largest budget) and *efficiency*: P = (seeds better + ties / 2) / seeds, with its exact "
        "95% interval; **credited** / **better** when it lies above 0.5, **worse** below, not credited / no clear "
        f"difference otherwise; {HOLM_MARK}: the verdict also holds under Holm's correction within the experiment's "
        f"family. Threshold: a normalised score of {summary.reference_threshold} "
        f"(without a reference: {summary.threshold_fraction:.0%} of the best method's gap); "
        "transitions to it: those counted at the smallest budget from which a seed stays at or above it. Data: "
        "`shared` (the random-policy stream every method shares), `reset` (privileged: one-step transitions from "
        "states spread over the target's box), `online` (epsilon-greedy episodes), `source-policy` "
        "(the grid planner's run of the projected source policy, the paper's protocol)." + _kernels_sentence(summary)
    )


def _kernels_sentence(summary: Summary) -> str:
    """Which arithmetic kernels computed the records (per-seed returns depend on them), so a
    table copied elsewhere still says what produced it; empty when no record names them."""
    known = summary.known_kernels
    if not known:
        return ""
    older = sum(summary.kernels.values()) - sum(known.values())
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


def _experiment_section(summary: Summary, exp: Experiment) -> list[str]:
    """One experiment's heading, verdicts, method table and footnote."""
    methods = sorted(exp.methods, key=order)
    # Methods the experiment's own spec lists but that finished no seed are flagged;
    # other experiments' methods are not this one's business.
    listed = list(exp.spec_methods or summary.methods)
    comparison = comparison_of(exp, methods + [m for m in listed if m not in methods])
    lines = [f"### {exp.spec.get('title', exp.name)} (`{exp.name}`)", ""]
    claim = exp.spec.get("paper_claim")
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
    if exp.verdicts is not None:
        lines += _verdict_rows(exp) + [""]
    elif sentences := verdicts.ablation_sentences(
        exp.spec_methods, comparison
    ):  # no reference return: a sentence per ablation
        lines += ["Transfer against its ablation without the source:", ""]
        lines += [f"- {v}" for v in sentences] + [""]
    lines += _method_rows(exp, comparison)
    lines += apprentice_rows(exp, comparison)
    lines += _capped_lines(exp)
    return lines + _footnote(summary, exp, comparison)


def _method_rows(exp: Experiment, comparison: Comparison) -> list[str]:
    """The method table: one row per compared method."""
    stats_on = any(exp.methods[r.method].efficiency is not None for r in comparison.methods)
    header = "| method | data | final return: mean ± sd (median) | transitions to threshold, counted: median (seeds) "
    header += "| paper's accounting: median "
    if stats_on:
        header += (
            "| first policy after, counted / paper's | normalised final score: IQM [95% CI] "
            "| efficiency: IQM [95% CI] | efficiency, paper's accounting "
        )
    lines = [header + "|", "|---" * header.count("|") + "|"]
    for r in comparison.methods:
        data = exp.methods[r.method]
        finals = np.asarray(r.final_returns)
        final = f"{finals.mean():.4g} ± {finals.std():.2g} ({np.median(finals):.4g})"
        if comparison.meaningful:
            first = min(data.curve.samples)
            left = sum(1 for v in r.samples_to_threshold if math.isfinite(v) and v <= first)
            censored = f", {left} at the smallest budget" if left else ""
            counted = f"{samples_text(r.median_samples)} ({r.reached}/{len(r.seeds)} reached{censored})"
            paper = samples_text(r.median_samples_paper)
        else:
            counted, paper = "no meaningful threshold", "n/a"
        row = f"| {method_label(r.method)} | {data.data} | {final} | {counted} | {paper} "
        if stats_on:
            first_policy = data.first_policy or {}
            row += (
                f"| {samples_text(first_policy.get(verdicts.COUNTED))} "
                f"/ {samples_text(first_policy.get(verdicts.PAPER))} "
                f"| {interval_text(data.final_iqm)} | {interval_text(data.efficiency)} "
                f"| {interval_text(data.efficiency_paper)} "
            )
        lines.append(row + "|")
    return lines


def apprentice_samples(exp: Experiment, method: str, seeds: Sequence[int]) -> list[float] | None:
    """Per budget, the median over ``seeds`` of the shared samples ``method``'s apprentice was
    fitted on (``samples_used``: those Algorithm 2 kept); None in a summary older than them."""
    data = exp.methods[method]
    used = data.curve.samples_used
    if used is None or not seeds:
        return None
    rows = np.asarray(used, dtype=float)[data.rows(list(seeds))]
    return [float(v) for v in np.median(rows, axis=0)]


def apprentice_rows(exp: Experiment, comparison: Comparison) -> list[str]:
    """A small table under the method table: per TA-TL method (every table building a ``ta-tl``
    method), the apprentice's samples at each budget, median over the compared seeds; nothing
    where no TA-TL method is compared or the summary is older than the samples."""
    shown = []
    for r in comparison.methods:
        settings = exp.spec_methods.get(r.method)
        base = (settings or {}).get("method", r.method) if isinstance(settings, Mapping) else r.method
        medians = apprentice_samples(exp, r.method, r.seeds) if str(base).startswith("ta-tl") else None
        if medians is not None:
            shown.append((r.method, medians))
    if not shown:
        return []
    budgets = exp.methods[shown[0][0]].curve.samples
    lines = [
        "",
        "Samples the apprentice was fitted on (median over the compared seeds; Algorithm 2 may stop "
        "before the budget), per budget:",
        "",
        "| method | " + " | ".join(samples_text(b) for b in budgets) + " |",
        "|---" * (len(budgets) + 1) + "|",
    ]
    for method, medians in shown:
        cells = (f"{v:,.0f}" if v == round(v) else f"{v:,.1f}" for v in medians)  # a median of an even count
        lines.append(f"| {method_label(method)} | " + " | ".join(cells) + " |")
    return lines


def answer_text(answer: Answer | None, words: dict[str, str] = VERDICT_WORDS) -> tuple[str, str]:
    """``(P [CI] (better/tied/worse), verdict)`` of one question of a pair, "-" where not asked."""
    if answer is None:
        return "-", "-"
    seeds = answer.seeds
    mark = HOLM_MARK if answer.holm else ""
    return (
        f"{interval_text(answer.probability)} ({seeds['better']}/{seeds['tied']}/{seeds['worse']})",
        words[answer.verdict] + mark,
    )


def _verdict_rows(exp: Experiment) -> list[str]:
    """The verdicts of the declared pairs, both questions each."""
    pairs = exp.verdicts or ()
    if not pairs:
        return ["No declared pair has both of its methods here: no verdict."]
    families = exp.families or {}
    lines = [
        f"Verdicts (P = (better + tied / 2) / seeds, seeds better/tied/worse in brackets; the family holds "
        f"{families.get('final', '?')} pairs asking *final* and {families.get('efficiency', '?')} asking "
        f"*efficiency*; intervals unadjusted, {HOLM_MARK} where Holm's correction keeps the verdict):",
        "",
        "| method | against | final: P [95% CI] | median difference [95% CI] | verdict "
        "| efficiency: P [95% CI] | verdict | efficiency, paper's accounting: verdict |",
        "|---|---|---|---|---|---|---|---|",
    ]
    marked = privileged(exp.spec_methods)
    for pair in ordered(pairs, marked, READINGS):
        final_p, final_v, efficiency_p, efficiency_v, paper_v = _answer_cells(pair, exp)
        difference = "-" if pair.final is None else interval_text(pair.final.median_difference, "+.2f")
        other = against(pair, marked)
        if pair.parents:
            other += f" (the parent `{exp.spec.get('streams')}`'s records)"
        lines.append(
            f"| {method_cell(pair.method, marked)} | {other} | {final_p} | {difference} | {final_v} "
            f"| {efficiency_p} | {efficiency_v} | {paper_v} |"
        )
    return lines


def _capped_lines(exp: Experiment) -> list[str]:
    """Survival to the episode cap and steadiness, where the target has them."""
    lines: list[str] = []
    survived = {m: d.survival for m, d in exp.methods.items() if d.survival is not None}
    if survived:
        parts = [
            f"{method_label(m)} {v.at_cap:.2f} ({v.episodes} episodes, seeds {seed_range(list(v.seeds))})"
            for m, v in survived.items()
        ]
        lines += [
            "",
            "Kaplan-Meier survival to the episode cap at the largest budget (episodes pooled over the "
            "compared seeds; only methods with an episode that ended early): " + "; ".join(parts) + ".",
        ]
    steady = {m: d.steadiness for m, d in exp.methods.items() if d.steadiness is not None}
    if steady:
        seeds = sorted({seed_range(list(d.steadiness_seeds)) for d in exp.methods.values() if d.steadiness})
        lines += ["", _steadiness_sentence(steady) + f" Seeds: {'; '.join(seeds)}."]
    return lines


def _footnote(summary: Summary, exp: Experiment, comparison: Comparison) -> list[str]:
    """The line under an experiment: random return, threshold rule, the area's range, the mapping's samples."""
    threshold = "none" if comparison.threshold is None else f"{comparison.threshold:.4g}"
    mapping = sorted(set(exp.mapping_target_samples))
    reference_return = exp.reference_return
    rule = (
        f"reference return {reference_return:.4g} (fixed; threshold at a normalised score of "
        f"{summary.reference_threshold})"
        if reference_return is not None
        else "no reference return declared: the threshold is relative to the best method listed"
    )
    span = exp.efficiency_range
    area = f"; efficiency over {span[0]:,.0f} to {span[1]:,.0f} transitions" if span else ""
    return [
        "",
        f"Random policy: {comparison.random_return:.4g}; {rule}; threshold: {threshold}{area}; target samples "
        f"used to learn the mapping (shared by TA-TL and UMA-TL, not counted above): {mapping}.",
        "",
    ]


def _steadiness_sentence(steady: dict[str, Mapping[str, Interval]]) -> str:
    """One line: each method's steadiness at the largest budget (IQM over seeds [95% CI])."""
    units = {"roll_rms": ("roll RMS", "deg", 180 / math.pi), "mean_abs_action": ("mean |action|", "", 1.0)}
    parts = []
    for method, measures in sorted(steady.items(), key=lambda kv: order(kv[0])):
        shown = []
        for name, estimate in measures.items():
            label, unit, scale = units.get(name, (name, "", 1.0))
            scaled = Interval(
                *(None if v is None else v * scale for v in (estimate.value, estimate.low, estimate.high))
            )
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


def aggregate_table(summary: Summary) -> str:
    """Each method's IQM of normalised final scores over every experiment and seed it ran."""
    rows = summary.aggregate
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
    for name in sorted(rows, key=lambda m: -(rows[m].estimate.value or -math.inf)):
        r = rows[name]
        lines.append(f"| {method_label(name)} | {r.experiments} | {r.runs} | {interval_text(r.estimate)} |")
    return "\n".join(lines) + "\n"


def credit_table(name: str, cells: list[tuple[dict, Experiment]]) -> str:
    """Per sweep condition, each transfer method against its ablation and placebo, both questions."""
    credit = (verdicts.ABLATION, verdicts.PLACEBO)
    marked = privileged(cells[0][1].spec_methods)
    keys = sorted(
        {(v.method, v.other) for _, exp in cells for v in exp.verdicts or () if v.role in credit},
        key=lambda k: (k[0], not no_more_resources(marked, *k), k[1]),
    )
    params = list(cells[0][0])
    header = (
        "| "
        + " | ".join(params)
        + " | "
        + " | ".join(f"{_pair_heading(m, a, marked)}: final; efficiency" for m, a in keys)
        + " |"
    )
    lines = [f"### Credit map: `{name}`", "", header, "|---" * (len(params) + len(keys)) + "|"]
    for condition, exp in cells:
        found = {(v.method, v.other): v for v in exp.verdicts or ()}
        row = [str(condition[k]) for k in params]
        for key in keys:
            pair = found.get(key)
            if pair is None:
                row.append("n/a")
                continue
            parts = [" ".join(answer_text(pair.answer(q))) for q in verdicts.QUESTIONS]
            row.append("; ".join(parts))
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines + [""])


def _pair_heading(method: str, other: str, marked: Mapping[str, frozenset[str]]) -> str:
    """``method`` > ``other``, each side labelled privileged where it is, and the pair marked as
    information where the comparator holds a privilege the method lacks (:func:`credits`)."""
    note = "" if no_more_resources(marked, method, other) else f" ({INFORMATION}: {NOT_CREDIT})"
    return f"{method_cell(method, marked)} > {method_cell(other, marked)}{note}"


# --- the headline tables --------------------------------------------------------------


def _answer_cells(pair: PairVerdict, exp: Experiment) -> tuple[str, str, str, str, str]:
    """A pair's final P and verdict, efficiency P and verdict, and the paper-accounting verdict
    (without the Holm mark: that question is not in the family), with :func:`why_accountings_differ`."""
    words = verdicts.words(pair.role, marked=True)
    final_p, final_v = answer_text(pair.final, words)
    efficiency_p, efficiency_v = answer_text(pair.efficiency, words)
    paper_v = answer_text(pair.efficiency_paper, words)[1].rstrip(HOLM_MARK)
    why = why_accountings_differ(pair, exp)
    paper_v += f" ({why})" if why else ""
    notes = []
    if not credits(pair, privileged(exp.spec_methods)):
        notes.append(INFORMATION)
    if more_actions(pair, exp.spec_methods):
        notes.append(MORE_ACTIONS)
    if notes:
        mark = f" ({'; '.join(notes)})"
        final_v, efficiency_v, paper_v = (v if v == "-" else v + mark for v in (final_v, efficiency_v, paper_v))
    return final_p, final_v, efficiency_p, efficiency_v, paper_v


def why_accountings_differ(pair: PairVerdict, exp: Experiment) -> str:
    """Where the efficiency verdict on counted transitions differs from the one on the paper's
    accounting, what each method paid before its first policy (median over seeds, counted / the
    paper's), which is where the two accountings part: Algorithm 2's U_M rollouts; else ""."""
    counted, paper = pair.efficiency, pair.efficiency_paper
    if counted is None or paper is None or counted.verdict == paper.verdict:
        return ""
    paid = []
    for name in (pair.method, pair.other):
        first = exp.methods[name].first_policy if name in exp.methods else None
        if first:
            mine, theirs = first.get(verdicts.COUNTED), first.get(verdicts.PAPER)
            paid.append(f"`{name}` {samples_text(mine)}" + (f" / {samples_text(theirs)}" if theirs != mine else ""))
    return "before a first policy, counted / paper's: " + "; ".join(paid) if paid else ""


def verdict_table(
    summary: Summary,
    prefix: str = "",
    roles: Sequence[str] = (verdicts.ABLATION, verdicts.PLACEBO),
    methods: Sequence[str] | None = None,
    credited_only: bool = False,
    experiments: Sequence[str] | None = None,
) -> str:
    """One row per declared pair of the given roles whose method starts with ``prefix`` (or is one of
    ``methods``), both questions: the README's credit tables (a variant's pairs that are its
    parent's are left out). ``credited_only``: only pairs credited (or better) on either question.
    ``experiments``: only these (default: every one).
    Per experiment the rows go by method (``methods``' order), each method's non-privileged
    comparator before the privileged one beside it; a verdict against a privileged comparator is
    printed as information (:func:`credits`), and one of a reading with more actions than its
    comparator says so (:func:`more_actions`)."""
    lines = [
        "| experiment | method | against | final: P [95% CI] | verdict | efficiency: P [95% CI] | verdict "
        "| efficiency, paper's accounting | normalised final score, method / against |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, exp in summary.experiments.items():
        if experiments is not None and name not in experiments:
            continue
        title = exp.spec.get("title", exp.spec["name"])
        marked = privileged(exp.spec_methods)
        for pair in ordered(exp.verdicts or (), marked, methods or ()):
            if pair.role not in roles or pair.parents or not pair.method.startswith(prefix):
                continue
            if methods is not None and pair.method not in methods:
                continue
            answers = (pair.answer(q) for q in verdicts.QUESTIONS)
            if credited_only and not any(a is not None and a.verdict == verdicts.CREDITED for a in answers):
                continue
            final_p, final_v, efficiency_p, efficiency_v, paper_v = _answer_cells(pair, exp)
            mine, theirs = (exp.methods[m].final_iqm for m in (pair.method, pair.other))
            lines.append(
                f"| {title} | {method_cell(pair.method, marked)} | {against(pair, marked)} | {final_p} "
                f"| {final_v} | {efficiency_p} | {efficiency_v} | {paper_v} "
                f"| {interval_text(mine)} / {interval_text(theirs)} |"
            )
    return "\n".join(lines)


def reproduced(to_threshold: dict[str, float | None], method: str = "ta-tl") -> str:
    """The paper's central claim, TA-TL reaches the threshold with fewer samples than UMA-TL and
    RL, read from the median samples to threshold on the paper's protocol and accounting (``method``:
    the reading of TA-TL's action): ``yes`` fewer than both, ``partly`` fewer than one, ``no``
    otherwise (TA-TL never reaching it included)."""
    mine = to_threshold.get(method)
    if mine is None or math.isinf(mine):
        return "no"
    others = [to_threshold.get(m) for m in ("uma-tl", "rl")]
    fewer = sum(1 for v in others if v is None or math.isinf(v) or mine < v)
    return {2: "yes", 1: "partly"}.get(fewer, "no")


def paper_table(summary: Summary) -> str:
    """The paper's own comparison first: per experiment the paper's claim and numbers, then a row per
    reading of TA-TL's action (:data:`READINGS`, of equal standing): ours on the paper's protocol and
    accounting (the shared random-policy stream, apprentice samples only), ours counted (Algorithm
    2's rollouts included), and whether the claim is reproduced."""
    lines = [
        "| experiment | the paper | the paper's numbers | TA-TL's actions | here, paper's accounting: median "
        "transitions to threshold, TA-TL / UMA-TL / RL | here, counted: TA-TL | normalised final score (IQM), "
        "TA-TL / UMA-TL / RL | reproduced |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for exp in summary.experiments.values():
        spec = exp.spec
        paper = spec.get("paper") or {}
        if not paper:
            continue  # a variant or sweep of ours: no claim of the paper's to compare
        shown = [m for m in READINGS if m in exp.methods] or [READINGS[0]]
        for i, reading in enumerate(shown):
            names = (reading, *PAPER_METHODS[1:])
            comparison = comparison_of(exp, [m for m in names if m in exp.methods])
            medians = {r.method: r.median_samples_paper for r in comparison.methods if comparison.meaningful}
            counted = comparison.result(reading)
            finals = " / ".join(interval_text(exp.methods[m].final_iqm if m in exp.methods else None) for m in names)
            claim = (
                f"{spec.get('title', spec['name'])} | {paper.get('section', '')} | {paper.get('numbers', '')}"
                if i == 0
                else "as above | |"
            )
            lines.append(
                f"| {claim} | `{reading}` ({READING_LABELS.get(reading, reading)}) "
                f"| {' / '.join(samples_text(medians.get(m)) for m in names)} "
                f"| {samples_text(counted.median_samples if counted else None)} | {finals} "
                f"| {reproduced(medians, reading)} |"
            )
    return "\n".join(lines)


__all__ = [
    "CREDIT_READING",
    "PAPER_METHODS",
    "READINGS",
    "aggregate_table",
    "apprentice_rows",
    "apprentice_samples",
    "answer_text",
    "credit_table",
    "paper_table",
    "reproduced",
    "seed_note",
    "table",
    "verdict_table",
]
