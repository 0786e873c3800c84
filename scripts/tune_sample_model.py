"""``apprentice-fqi-samples``'s settings on the tuning seeds, by the criterion docs/protocol.md
declares ("Seeds", "`apprentice-fqi-samples`: declared before its tuning run").

1. ``reward_features``: the FQI basis, or it plus one wide RBF, by the lower median held-out
   reward RMSE over seeds 0-9 and the paper budgets, per target domain (within 1 %: the plain
   basis). Computed on each seed's shared target stream with the method's own holdout and seed;
   no policy is learned.
2. ``rounds`` x ``horizon`` in {0; 2 x 100; 4 x 200} with (1)'s choice, by the highest mean over
   the three pendulum experiments of the median over seeds 0-9 of the efficiency area (counted
   transitions; a difference under 0.01 is a tie, to the fewer rollout steps). Run through
   ``tatl run --preset paper --seeds 10 --first-seed 0 --methods ...`` on spec variants written
   under OUT/specs that extend the shipped specs (same name, so the same draws) and add the
   candidate tables only. Rerunning resumes.

    PYTHONPATH=. .venv/bin/python scripts/tune_sample_model.py [OUT] [--workers N]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from tatl_mj.experiments.run.problems import learning_seed
from tatl_mj.experiments.run.sides import description_of
from tatl_mj.experiments.run.source_unit import target_stream
from tatl_mj.experiments.spec import load_spec
from tatl_mj.transfer.reward_model import held_out_errors, reward_bases

ROOT = Path(__file__).resolve().parent.parent
SEEDS = range(10)
PRESET = "paper"
PENDULUM = ("ip_to_flipped_ip", "ip_to_timevarying_ip", "mc_to_ip")
BICYCLE = ("cartpole_to_bicycle",)
WIDE = {
    "pendulum": {"kind": "rbf", "centers": [[0.0, 0.0]], "sigma": [3.0, 8.0], "periodic": [True, False]},
    "bicycle": {"kind": "rbf", "centers": [[0.0, 0.0, 0.0, 0.0]], "sigma": [1.0, 3.0, 0.42, 3.0]},
}
SCHEDULES = {"r0": (0, 100), "r2h100": (2, 100), "r4h200": (4, 200)}  # rounds, horizon; cheapest first
TIE_RMSE, TIE_AREA = 0.01, 0.01


def base_table(spec) -> dict:
    """The shipped ``apprentice-fqi`` table's apprentice and FQI learner (apprentice-fqi-samples's)."""
    table = dict(spec.methods["apprentice-fqi"])
    return {k: v for k, v in table.items() if k != "model_samples"}


def reward_errors(name: str, wide: dict) -> dict[str, float]:
    """Per reward basis, the median held-out reward RMSE over seeds and budgets."""
    spec = load_spec(ROOT / "tasks" / f"{name}.toml")
    preset = spec.preset(PRESET)
    plain = base_table(spec)["features"]
    target = description_of(spec.target)
    bases = {"plain": plain, "plus-wide": [plain, wide]}
    errors: dict[str, list[float]] = {k: [] for k in bases}
    for seed in SEEDS:
        stream = target_stream(spec, preset, seed)
        for budget in preset.target_budgets:
            data = stream.head(budget)
            for key, basis in bases.items():
                rng = np.random.default_rng(learning_seed(spec, seed))
                fitted = reward_bases(basis, target.state_dim)
                held = held_out_errors(data, fitted, "next", target.n_actions, 1e-6, holdout=0.2, rng=rng)
                if held.reward_rmse is not None:
                    errors[key].append(held.reward_rmse)
    return {k: float(np.median(v)) for k, v in errors.items()}


def choose_basis(medians: dict[str, float]) -> str:
    plain, wide = medians["plain"], medians["plus-wide"]
    return "plus-wide" if wide < plain * (1 - TIE_RMSE) else "plain"


def write_variant(out: Path, name: str, reward_features) -> Path:
    spec = load_spec(ROOT / "tasks" / f"{name}.toml")
    table = base_table(spec)
    lines = [f'extends = "{ROOT / "tasks" / (name + ".toml")}"', ""]
    for key, (rounds, horizon) in SCHEDULES.items():
        lines.append(f"[methods.afs-{key}]")
        settings = {"method": "apprentice-fqi-samples", **table, "rounds": rounds, "horizon": horizon}
        settings["reward_features"] = reward_features
        lines += [f"{k} = {_toml(v)}" for k, v in settings.items()]
        lines.append("")
    path = out / "specs" / f"{name}.toml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines))
    return path


def _toml(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + " }"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return json.dumps(value)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("out", nargs="?", default="runs/tune_sample_model")
    parser.add_argument("--workers", type=int, default=1)
    args = parser.parse_args()
    out = Path(args.out)
    print("1. reward_features: median held-out reward RMSE over seeds 0-9 and the paper budgets")
    chosen = {}
    for domain, names in (("pendulum", PENDULUM), ("bicycle", BICYCLE)):
        per = {name: reward_errors(name, WIDE[domain]) for name in names}
        for name, medians in per.items():
            print(f"   {name}: " + ", ".join(f"{k} {v:.4g}" for k, v in medians.items()), flush=True)
        pooled = {k: float(np.median([m[k] for m in per.values()])) for k in ("plain", "plus-wide")}
        chosen[domain] = choose_basis(pooled)
        print(f"   {domain} (median of the experiments' medians): {pooled} -> {chosen[domain]}", flush=True)
    plain = base_table(load_spec(ROOT / "tasks" / f"{PENDULUM[0]}.toml"))["features"]
    features = plain if chosen["pendulum"] == "plain" else [plain, WIDE["pendulum"]]
    specs = [str(write_variant(out, name, features)) for name in PENDULUM]
    methods = ",".join(f"afs-{k}" for k in SCHEDULES)
    command = [
        sys.executable,
        "-m",
        "tatl_mj.cli",
        "run",
        *specs,
        "--preset",
        PRESET,
        "--seeds",
        str(len(SEEDS)),
        "--first-seed",
        str(SEEDS[0]),
        "--methods",
        methods,
        "--workers",
        str(args.workers),
        "--out",
        str(out / "run"),
    ]
    print("2. rounds x horizon:", " ".join(command), flush=True)
    subprocess.run(command, check=True)
    summary = json.loads((out / "run" / "summary.json").read_text())
    scores = {}
    for key in SCHEDULES:
        medians = []
        for name in PENDULUM:
            area = summary["experiments"][name]["methods"][f"afs-{key}"]["efficiency"]["per_seed"]
            medians.append(float(np.median(area)))
        scores[key] = float(np.mean(medians))
        print(f"   {key}: median areas " + ", ".join(f"{m:.3f}" for m in medians) + f"; mean {scores[key]:.3f}")
    best = max(scores.values())
    choice = next(k for k in SCHEDULES if scores[k] > best - TIE_AREA)  # cheapest within the tie
    print(f"choice: reward_features {chosen}, rounds x horizon {SCHEDULES[choice]} ({choice})")


if __name__ == "__main__":
    main()
