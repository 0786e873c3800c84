"""Stable-Baselines3 SAC agents on the flipped pendulum, scored on the gain sweep with `tatl evaluate`.

Three agents, each on tatl_mj/PendulumSwingupFlipped-v2 through the native vector env
(tatl_mj.sb3), each within a wall-clock budget (--minutes) and a step budget (--steps):

- randomised: the flipped control's gain drawn uniform on [0.5, 2] at every episode
  (the vector env's ContextSampler), the observation the task state alone;
- context: the same draws, the context (mass, length, gravity, gain) appended to the
  observation (``context_in_observation=True``);
- nominal: the paper's gain (1) only.

Each model is saved (DIR/NAME/model.zip) and scored on every condition of
tasks/sweeps/ip_to_flipped_ip_gain.toml by `tatl evaluate` (DIR/NAME/evaluation: the
spec's evaluation starts and seeds, normalised between the random policy and the
preset's reference return, as its methods are; the context agent with
--context-in-observation), then `tatl plot` draws the three side by side
(DIR/scores.png). The angle reaches the networks as its cosine and sine inside the
policy (tatl_mj.sb3.PeriodicFeatures), so a saved model takes the raw observation.
Needs the sb3 extra (``pip install 'tatl-mj[sb3]'``).

    python scripts/sb3_flipped_gain.py --minutes 10 --out runs/sb3_flipped_gain
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path

import torch
from stable_baselines3 import SAC
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecMonitor

from tatl_mj import sb3, suite
from tatl_mj.cli import main as tatl

ENV_ID = "tatl_mj/PendulumSwingupFlipped-v2"
SWEEP = Path(__file__).resolve().parents[1] / "tasks" / "sweeps" / "ip_to_flipped_ip_gain.toml"
GAINS = (0.5, 2.0)  # the sweep's range of the flipped control's gain
AGENTS = ("randomised", "context", "nominal")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="wall-clock training budget per agent")
    parser.add_argument("--steps", type=int, default=200_000, help="env steps per agent (all envs together)")
    parser.add_argument("--envs", type=int, default=8, help="envs of the vector env")
    parser.add_argument("--agents", default=",".join(AGENTS), help=f"which of {', '.join(AGENTS)}")
    parser.add_argument("--out", default="runs/sb3_flipped_gain", help="output folder")
    parser.add_argument("--seed", type=int, default=0, help="the agents' seed (training only)")
    parser.add_argument("--preset", default="paper", help="the sweep's preset that scores them (default: paper)")
    parser.add_argument("--eval-seeds", type=int, default=None, help="tatl evaluate --seeds (default: the preset's)")
    args = parser.parse_args()
    agents = [a.strip() for a in args.agents.split(",") if a.strip()]
    unknown = sorted(set(agents) - set(AGENTS))
    if unknown:
        parser.error(f"unknown agents {unknown}; valid: {', '.join(AGENTS)}")

    # One torch thread: the envs step on MuJoCo's threads, and on a few cores torch's own
    # threads waiting on each other cost more than they compute (scripts/sac_pendulum.py).
    torch.set_num_threads(1)
    out = Path(args.out)
    folders = []
    for name in agents:
        model = train(name, args)
        path = out / name / "model.zip"
        path.parent.mkdir(parents=True, exist_ok=True)  # SB3 would warn, then create it
        model.save(path)
        folders.append(str(evaluate(name, path, model.num_timesteps, args)))
    figure = out / "scores.png"
    if tatl(["plot", *folders, "--out", str(figure)]) != 0:
        raise SystemExit("tatl plot failed")


def train(name: str, args: argparse.Namespace) -> SAC:
    """One agent, trained until its step or wall-clock budget runs out."""
    kwargs: dict = {}
    if name != "nominal":
        kwargs["contexts"] = suite.ContextSampler({"gain": GAINS}, seed=args.seed)
    if name == "context":
        kwargs["context_in_observation"] = True
    envs = VecMonitor(sb3.vec_env(ENV_ID, args.envs, **kwargs))
    envs.seed(args.seed)
    periodic = list(suite.describe("pendulum", "swingup_flipped").periodic)
    # The settings of scripts/sac_pendulum.py: the reward is about -100 a step hanging down, so
    # a larger learning rate and a gradient step for every transition collected.
    model = SAC(
        "MlpPolicy",
        envs,
        learning_rate=1e-3,
        learning_starts=min(1_000, args.steps // 2),
        gradient_steps=args.envs,
        policy_kwargs={
            "net_arch": [64, 64],
            "features_extractor_class": sb3.PeriodicFeatures,
            "features_extractor_kwargs": {"periodic": periodic},
        },
        seed=args.seed,
        device="cpu",
    )
    began = time.perf_counter()
    model.learn(total_timesteps=args.steps, callback=WallClock(args.minutes * 60.0))
    print(f"{name}: trained {model.num_timesteps} steps in {time.perf_counter() - began:.0f} s")
    return model


def evaluate(name: str, model: Path, steps: int, args: argparse.Namespace) -> Path:
    """`tatl evaluate` of one saved agent on the sweep; returns its folder."""
    folder = model.parent / "evaluation"
    argv = ["evaluate", str(SWEEP), "--policy", str(model), "--out", str(folder), "--preset", args.preset]
    argv += ["--name", f"SAC {name}", "--transitions", str(steps), "--command", shlex.join([sys.executable, *sys.argv])]
    if name == "context":
        argv.append("--context-in-observation")
    if args.eval_seeds is not None:
        argv += ["--seeds", str(args.eval_seeds)]
    print("tatl " + shlex.join(argv))
    if tatl(argv) != 0:
        raise SystemExit(f"tatl evaluate failed for {name}")
    return folder


class WallClock(BaseCallback):
    """Stops training once ``seconds`` of wall-clock time have passed."""

    def __init__(self, seconds: float) -> None:
        super().__init__()
        self.seconds = seconds
        self.began = time.perf_counter()

    def _on_training_start(self) -> None:
        self.began = time.perf_counter()

    def _on_step(self) -> bool:
        return time.perf_counter() - self.began < self.seconds


if __name__ == "__main__":
    main()
