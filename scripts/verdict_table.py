"""The README's credit table from a run's summary.json: one row per transfer method and the
method it must beat (its source-free ablation, or its placebo source), both verdict questions.

    python scripts/verdict_table.py runs/paper/summary.json [PREFIX]

With PREFIX (e.g. ``ta-tl``) only the methods whose names start with it.
"""

from __future__ import annotations

import sys

from tatl_mj.experiments.report.tables import verdict_table
from tatl_mj.experiments.results import summary_data

if __name__ == "__main__":
    prefix = sys.argv[2] if len(sys.argv) > 2 else ""
    print(verdict_table(summary_data.read(sys.argv[1]), prefix))
