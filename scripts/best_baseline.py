"""Each experiment's best baseline per verdict question, from a run on the tuning seeds, as the
``best_baseline`` line its spec freezes (``verdicts.choose_best_baseline``: the baseline with
the highest IQM of the question's per-seed statistic; ties to the one listed first).

    tatl run tasks/*.toml tasks/variants/*.toml --preset paper --seeds 10 --first-seed 0 --out runs/tuning
    python scripts/best_baseline.py runs/tuning/summary.json
"""

from __future__ import annotations

import sys

from tatl_mj.experiments.results import pairs, summary_data, verdicts

if __name__ == "__main__":
    summary = summary_data.read(sys.argv[1])
    for name, experiment in summary.experiments.items():
        chosen = verdicts.choose_best_baseline(experiment.methods, pairs.baselines(experiment.spec["methods"]))
        table = ", ".join(f'{q} = "{b}"' for q, b in chosen.items())
        print(f"{name}: best_baseline = {{ {table} }}")
