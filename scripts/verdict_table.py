"""The README's verdict table from a run's summary.json: one row per transfer method and
the method it must beat (its source-free ablation, or its placebo source), one line a cell.

    python scripts/verdict_table.py runs/paper/summary.json [PREFIX]

With PREFIX (e.g. ``ta-tl``) only the methods whose names start with it.
"""

from __future__ import annotations

import json
import sys

from tatl_mj.experiments.plot import interval_text as interval

WORDS = {"credited": "**credited**", "worse": "**worse**", "not credited": "not credited"}


def rows(summary: dict, prefix: str = "") -> list[str]:
    lines = [
        "| experiment | method | against | P(method > against) [95% CI] | verdict | final score, method / against |",
        "|---|---|---|---|---|---|",
    ]
    for exp in summary["experiments"].values():
        title = exp["spec"].get("title", exp["spec"]["name"])
        pairs = [(p, "source-free") for p in exp.get("ablations", [])] + [
            (p, "placebo") for p in exp.get("placebo", [])
        ]
        for pair, kind in pairs:
            if not pair["method"].startswith(prefix):
                continue
            mine, theirs = (exp["methods"][m].get("final_iqm") for m in (pair["method"], pair["ablation"]))
            lines.append(
                f"| {title} | `{pair['method']}` | `{pair['ablation']}` ({kind}) "
                f"| {interval(pair['probability_of_improvement'])} | {WORDS[pair['verdict']]} "
                f"| {interval(mine)} / {interval(theirs)} |"
            )
    return lines


if __name__ == "__main__":
    prefix = sys.argv[2] if len(sys.argv) > 2 else ""
    print("\n".join(rows(json.load(open(sys.argv[1], encoding="utf-8")), prefix)))
