"""``apprentice-fqi-samples``'s warm rounds on the tuning seeds, by the criterion docs/protocol.md
declares ("`apprentice-fqi-samples`'s warm rounds: declared before their tuning run").

One candidate, ``round_iterations = iterations / 4`` for both twins in every spec, run through
``tatl run --preset paper --seeds 10 --first-seed 0 --methods apprentice-fqi-samples,
apprentice-fqi-samples-rbf`` on spec variants written under OUT/specs that extend the shipped
specs (same name, so the same draws) and set only ``round_iterations``; judged seed by seed
against the cold schedule's records of the same seeds in the ``paper-tuning`` reference set
(``tatl reference unpack paper-tuning``). Adopted iff

1. over the eight cells (the two twins on the four experiments), the mean of the cells' median
   paired differences, warm minus cold, is at least -0.01 for the efficiency area and for the
   normalised final score; and
2. the verdict rule, reading warm as the method and cold as its comparator, calls warm worse on
   neither question in any cell.

    PYTHONPATH=. .venv/bin/python scripts/tune_warm_start.py [OUT] [--workers N]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from tatl_mj.experiments.results.verdicts import WORSE, answer
from tatl_mj.experiments.spec import load_spec

ROOT = Path(__file__).resolve().parent.parent
SEEDS = range(10)
PRESET = "paper"
EXPERIMENTS = ("ip_to_flipped_ip", "ip_to_timevarying_ip", "mc_to_ip", "cartpole_to_bicycle")
METHODS = ("apprentice-fqi-samples", "apprentice-fqi-samples-rbf")
SHARE = 4  # round_iterations = iterations // SHARE
TIE = 0.01


def write_variant(out: Path, name: str) -> Path:
    spec = load_spec(ROOT / "tasks" / f"{name}.toml")
    lines = [f'extends = "{ROOT / "tasks" / (name + ".toml")}"', ""]
    for method in METHODS:
        iterations = int(spec.methods[method]["iterations"])
        lines += [f"[methods.{method}]", f"round_iterations = {iterations // SHARE}", ""]
    path = out / "specs" / f"{name}.toml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines))
    return path


def per_seed(summary: dict, name: str, method: str) -> dict[str, np.ndarray]:
    data = summary["experiments"][name]["methods"][method]
    if list(data["seeds"]) != list(SEEDS):
        raise SystemExit(f"{name}/{method}: seeds {data['seeds']}, expected {list(SEEDS)}")
    return {
        "efficiency": np.asarray(data["efficiency"]["per_seed"], float),
        "final": np.asarray(data["normalised"], float)[:, -1],
    }


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("out", nargs="?", default="runs/tune_warm_start")
    parser.add_argument("--workers", type=int, default=1)
    args = parser.parse_args()
    out = Path(args.out)
    cold_dir = out / "cold"
    if not (cold_dir / "summary.json").exists():
        tatl = [sys.executable, "-m", "tatl_mj.cli"]
        subprocess.run([*tatl, "reference", "unpack", "paper-tuning", "--out", str(cold_dir)], check=True)
    specs = [str(write_variant(out, name)) for name in EXPERIMENTS]
    command = [sys.executable, "-m", "tatl_mj.cli", "run", *specs, "--preset", PRESET]
    command += ["--seeds", str(len(SEEDS)), "--first-seed", str(SEEDS[0]), "--methods", ",".join(METHODS)]
    command += ["--workers", str(args.workers), "--out", str(out / "run")]
    print("run:", " ".join(command), flush=True)
    subprocess.run(command, check=True)
    warm_summary = json.loads((out / "run" / "summary.json").read_text())
    cold_summary = json.loads((cold_dir / "summary.json").read_text())
    medians: dict[str, list[float]] = {"efficiency": [], "final": []}
    worse = []
    print("cell: median warm - cold (efficiency, final); verdicts warm against cold")
    for name in EXPERIMENTS:
        for method in METHODS:
            warm, cold = per_seed(warm_summary, name, method), per_seed(cold_summary, name, method)
            words = []
            for question in medians:
                medians[question].append(float(np.median(warm[question] - cold[question])))
                result = answer(warm[question], cold[question])
                words.append(f"{question} {result.verdict} ({result.signs.as_dict()})")
                if result.verdict == WORSE:
                    worse.append(f"{name}/{method} {question}")
            shown = ", ".join(f"{medians[q][-1]:+.3f}" for q in medians)
            print(f"  {name}/{method}: {shown}; " + "; ".join(words))
    means = {q: float(np.mean(v)) for q, v in medians.items()}
    print("mean of the cells' medians: " + ", ".join(f"{q} {v:+.4f}" for q, v in means.items()))
    adopted = all(v >= -TIE for v in means.values()) and not worse
    print(f"worse cells: {worse or 'none'}")
    print(f"choice: round_iterations = iterations / {SHARE}" if adopted else "choice: the cold schedule stays")


if __name__ == "__main__":
    main()
