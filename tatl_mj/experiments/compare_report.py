"""What a comparison tells its user first: their own verdicts, and what the reference's seeds can resolve.

``tatl compare``'s ``results.md`` opens with one table of the user's methods, read from the
summary the comparison built: for each of their methods and experiment, the pairs it was
judged on (its declared ablation and placebo, the spec's frozen best baseline) with both
questions and the effect size, and beside them the same two questions against the built-in
TA-TL, answered as the rule answers a pair (``verdicts.answer``) but outside the rule's
families (no Holm correction counts it). A pair whose two methods both stay near random
(:data:`NEAR_RANDOM`) is flagged: an interval that says one wins there says little.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from tatl_mj.experiments.report import privileges
from tatl_mj.experiments.results import verdicts

NEAR_RANDOM = 0.1
"""A method is near random where its median normalised final score over the compared seeds is
below this: a tenth of the way from the random policy (0) to the spec's reference return (1).
docs/extending.md declares it with its reason; it flags a pair, it never changes a verdict."""

TA_TL = "ta-tl"
QUESTION_WORDS = {verdicts.FINAL: "final score", verdicts.EFFICIENCY: "efficiency"}


def resolution(n: int) -> str:
    """What a set of ``n`` seeds can resolve under the exact sign test, in one sentence."""
    needed = verdicts.seeds_to_credit(n)
    if needed is not None:
        return (
            f"On {n} seeds a pair is credited (or found worse) only when at least {needed} of the {n} seeds agree: "
            "the exact sign test's 95% interval then lies clear of 0.5."
        )
    fewest = next(m for m in range(n + 1, 100) if verdicts.seeds_to_credit(m) is not None)
    all_of = verdicts.sign_probability(verdicts.PairedSigns(n, 0, 0))
    return (
        f"On {n} seeds no pair can be credited or found worse, however clear: even {n} of {n} seeds better gives "
        f"the exact sign test's 95% interval [{all_of.low:.2f}, {all_of.high:.2f}], which holds 0.5 (it takes at "
        f"least {fewest} seeds); read its verdicts as a direction, not a result."
    )


def _per_seed(experiment: Mapping[str, Any], method: str, seeds: Sequence[int]) -> dict[str, np.ndarray] | None:
    """A method's per-seed final normalised score and efficiency area on ``seeds``, or None."""
    data = experiment["methods"].get(method) or {}
    if not data.get("normalised") or not (data.get("efficiency") or {}).get("per_seed"):
        return None
    at = {seed: i for i, seed in enumerate(data["seeds"])}
    if any(seed not in at for seed in seeds):
        return None
    final = [data["normalised"][at[s]][-1] for s in seeds]
    efficiency = [data["efficiency"]["per_seed"][at[s]] for s in seeds]
    return {verdicts.FINAL: np.array(final, dtype=float), verdicts.EFFICIENCY: np.array(efficiency, dtype=float)}


def _near_random(experiment: Mapping[str, Any], methods: Sequence[str]) -> bool:
    seeds = experiment.get("compared_seeds") or []
    scores = [_per_seed(experiment, m, seeds) for m in methods]
    return all(s is not None and float(np.median(s[verdicts.FINAL])) < NEAR_RANDOM for s in scores)


def _cell(answer: Mapping[str, Any] | None) -> str:
    if not answer:
        return "not asked"
    seeds = answer["seeds"]
    n = seeds["better"] + seeds["tied"] + seeds["worse"]
    tied = f", {seeds['tied']} tied" if seeds["tied"] else ""
    median = answer["median_difference"]["value"]
    effect = "" if median is None else f", median difference {median:+.2f}"
    return f"{answer['verdict']}: {seeds['better']} of {n} seeds better{tied}{effect}"


def _ta_tl_pair(experiment: Mapping[str, Any], method: str) -> dict | None:
    """``method`` against the built-in TA-TL on both questions, as the rule answers a pair."""
    seeds = experiment.get("compared_seeds") or []
    mine, theirs = _per_seed(experiment, method, seeds), _per_seed(experiment, TA_TL, seeds)
    if method == TA_TL or mine is None or theirs is None:
        return None
    entry: dict[str, Any] = {"method": method, "other": TA_TL, "role": "the built-in TA-TL, outside the rule"}
    for question in verdicts.QUESTIONS:
        entry[question] = verdicts.answer(mine[question], theirs[question]).as_dict()
    return entry


def rows(summary: Mapping[str, Any], methods: Sequence[str]) -> list[dict]:
    """Each user method's judged pairs, per experiment: ablation, placebo, best baseline (the
    rule's), then TA-TL; each with ``near_random`` set where both methods stay near random."""
    order = {verdicts.ABLATION: 0, verdicts.PLACEBO: 1, verdicts.BEST_BASELINE: 2}
    out = []
    for method in methods:
        for name, experiment in summary["experiments"].items():
            judged = [p for p in experiment.get("verdicts", []) if p["method"] == method and not p.get("parents")]
            judged.sort(key=lambda p: order.get(p["role"], 3))
            extra = _ta_tl_pair(experiment, method)
            for pair in judged + ([extra] if extra else []):
                near = _near_random(experiment, [pair["method"], pair["other"]])
                out.append({"experiment": name, **pair, "near_random": near})
    return out


def table(summary: Mapping[str, Any], methods: Sequence[str]) -> list[str]:
    """The user's verdicts as a markdown table (see the module docstring), with its key."""
    found = rows(summary, methods)
    if not found:
        return ["None of your methods has a judged pair here (no other method finished on its seeds)."]
    lines = [
        "| experiment | yours | against | final score | efficiency | note |",
        "|---|---|---|---|---|---|",
    ]
    marked = {
        name: privileges.privileged((experiment.get("spec") or {}).get("methods") or {})
        for name, experiment in summary["experiments"].items()
    }
    for row in found:
        notes = [f"both near random (median final score < {NEAR_RANDOM:g})"] if row["near_random"] else []
        held = marked[row["experiment"]]
        if not privileges.no_more_resources(held, row["method"], row["other"]):
            notes.append(f"privileged comparator: {privileges.NOT_CREDIT}")
        note = "; ".join(notes)
        role = row["role"] + (f", {privileges.PRIVILEGED}" if row["other"] in held else "")
        lines.append(
            f"| {row['experiment']} | `{row['method']}` | `{row['other']}` ({role}) | "
            f"{_cell(row.get(verdicts.FINAL))} | {_cell(row.get(verdicts.EFFICIENCY))} | {note} |"
        )
    lines += [
        "",
        "Median differences are in normalised score (final) and normalised area (efficiency), yours minus "
        "the other's; `not asked`: the rule does not ask that question of the pair (a best baseline is "
        "chosen for one). The TA-TL rows are answered as the rule answers a pair but belong to no verdict "
        "family.",
    ]
    return lines


__all__ = ["NEAR_RANDOM", "resolution", "rows", "table"]
