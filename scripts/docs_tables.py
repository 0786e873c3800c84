"""Writes the README's and the docs' result tables from the shipped reference sets, so a table and
its data cannot drift apart; ``--check`` only says which block differs (CI runs it).

    python scripts/docs_tables.py            # rewrite every generated block, and the figures
    python scripts/docs_tables.py --check    # exit 1 naming each block that differs

A generated block sits between ``<!-- begin: NAME -->`` and ``<!-- end: NAME -->``; everything
outside the markers is written by hand.
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
from pathlib import Path

from tatl_mj.experiments.report import credit_maps, figures, premises, tables
from tatl_mj.experiments.results import reference
from tatl_mj.experiments.results.summary_data import Summary

ROOT = Path(__file__).resolve().parents[1]
PAPER, SWEEPS = "paper-heldout", "sweeps-heldout"


def blocks(paper: Summary, sweeps: Summary) -> dict[tuple[str, str], str]:
    """(file, block name) -> the block's text."""
    credit = "\n".join(tables.credit_table(name, cells) for name, cells in credit_maps.sweeps(sweeps).items())
    return {
        ("README.md", "paper-vs-here"): tables.paper_table(paper),
        # The paper's five experiments; the mapping variants' rows are in docs/results-paper.md.
        ("README.md", "credit"): tables.verdict_table(paper, methods=tables.READINGS, experiments=_paper_five(paper)),
        ("docs/results-paper.md", "credited-anywhere"): tables.verdict_table(paper, credited_only=True),
        ("docs/results-paper.md", "results"): tables.table(paper) + "\n" + tables.aggregate_table(paper),
        ("docs/credit.md", "credit-tables"): credit,
        # Only a reference set with premises (record schema 3) has a "why" table: else the block is empty.
        ("docs/results-paper.md", "why"): premises.why_table(paper),
        # The README's: the same-actions reading (and the bicycle's ta-tl-h) on the paper's five.
        ("README.md", "why"): premises.why_table(
            paper, (tables.CREDIT_READING, "ta-tl-h", "ta-tl-replan"), _paper_five(paper)
        ),
    }


def _paper_five(summary: Summary) -> list[str]:
    """The experiments that are not a mapping variant (a variant names its parent in ``streams``)."""
    return [name for name, exp in summary.experiments.items() if not exp.spec.get("streams")]


def replace_block(text: str, name: str, body: str, where: str) -> str:
    # An empty block is the two markers on consecutive lines.
    pattern = re.compile(rf"(<!-- begin: {re.escape(name)} -->\n)(?:.*?\n)?(<!-- end: {re.escape(name)} -->)", re.S)
    if not pattern.search(text):
        raise SystemExit(f"{where}: no block '{name}' (<!-- begin: {name} --> ... <!-- end: {name} -->)")
    return pattern.sub(lambda m: m.group(1) + body.rstrip("\n") + "\n" + m.group(2), text)


def draw(summary: Summary, out: Path) -> None:
    """The figures of an unpacked set into ``out`` (docs/figures)."""
    for name, experiment in summary.experiments.items():
        if experiment.spec.get("condition"):
            continue
        figures.figure(name, experiment, out / f"{name}.png")
    maps = credit_maps.sweeps(summary)
    if summary.aggregate and not maps:
        figures.profile(summary, out / "performance_profile.png")
        premises.premises_figure(summary, out / "premises.png")  # draws nothing without premises
    for name, cells in maps.items():
        credit_maps.credit_map(name, cells, out / f"credit_{name}.png")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only compare; exit 1 if a block differs")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        summaries = {}
        for name in (PAPER, SWEEPS):
            summaries[name] = Summary.from_json(reference.unpack(reference.load(name), Path(tmp) / name))
            if not args.check:
                draw(summaries[name], ROOT / "docs" / "figures")
    stale = []
    for (file, name), body in blocks(summaries[PAPER], summaries[SWEEPS]).items():
        path = ROOT / file
        text = path.read_text()
        new = replace_block(text, name, body, file)
        if new != text:
            stale.append(f"{file}: block '{name}'")
            if not args.check:
                path.write_text(new)
    if args.check and stale:
        print("out of date with the reference sets (run python scripts/docs_tables.py):", file=sys.stderr)
        print("\n".join(f"  {s}" for s in stale), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
