"""Stable-Baselines3 SAC on tatl_mj/PendulumSwingup-v2, headless: train, evaluate, film.

Needs the sb3 extra (``pip install 'tatl-mj[sb3]'``). Trains on the native
vector env through tatl_mj.sb3 (all envs in one batched MuJoCo call), evaluates
the deterministic policy against random actions on the same seeds, then films
one episode to an mp4 from the same process: no GL library is loaded before
that first frame (docs/deep-rl.md). About 2 minutes on 2 cores at the defaults.

    python scripts/sac_pendulum.py --steps 8000 --out videos/sac_pendulum.mp4
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import SAC
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.vec_env import VecEnvWrapper, VecMonitor

from tatl_mj import render, sb3, suite

ENV_ID = "tatl_mj/PendulumSwingup-v2"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=8_000, help="env steps to train (all envs together)")
    parser.add_argument("--envs", type=int, default=4, help="envs of the vector env")
    parser.add_argument("--episodes", type=int, default=10, help="evaluation episodes")
    parser.add_argument("--video-seconds", type=float, default=10.0, help="length of the filmed episode")
    parser.add_argument("--out", default="sac_pendulum.mp4", help="the video (.mp4 or .gif)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    # One torch thread: the envs step on MuJoCo's threads, and on a few cores torch's own
    # threads waiting on each other cost more than they compute (measured on 2 cores: 13x).
    torch.set_num_threads(1)
    began = time.perf_counter()
    envs = VecMonitor(AngleFeatures(sb3.vec_env(ENV_ID, args.envs)))
    envs.seed(args.seed)
    # The pendulum's reward is about -100 a step hanging down: a larger learning rate and
    # gradient steps for every transition collected swing it up within the budget.
    model = SAC(
        "MlpPolicy",
        envs,
        learning_rate=1e-3,
        learning_starts=1_000,
        gradient_steps=args.envs,
        policy_kwargs={"net_arch": [64, 64]},
        seed=args.seed,
        device="cpu",
    )
    model.learn(total_timesteps=args.steps)
    trained = time.perf_counter()
    print(f"trained {model.num_timesteps} steps on {args.envs} envs in {trained - began:.1f} s")

    evaluation = VecMonitor(AngleFeatures(sb3.vec_env(ENV_ID, args.episodes)))
    evaluation.seed(args.seed + 1000)
    mean, std = evaluate_policy(model, evaluation, n_eval_episodes=args.episodes, deterministic=True)
    evaluation.seed(args.seed + 1000)
    random_mean, random_std = evaluate_policy(_Random(evaluation), evaluation, n_eval_episodes=args.episodes)
    print(
        f"return over {args.episodes} episodes of {ENV_ID}: SAC {mean:.0f} +- {std:.0f}, "
        f"random actions {random_mean:.0f} +- {random_std:.0f}"
    )

    env = gym.make(ENV_ID, render_mode="rgb_array", width=320, height=240)
    fps = env.metadata["render_fps"]
    observation, _ = env.reset(seed=args.seed + 2000)
    frames = [env.render()]  # the first frame: the GL backend is chosen and loaded here
    for _ in range(int(args.video_seconds * fps)):
        action, _ = model.predict(features(observation[None])[0], deterministic=True)
        observation, _, terminated, truncated, _ = env.step(action)
        frames.append(env.render())
        if terminated or truncated:
            break
    env.close()
    path = render.write_clip(np.stack(frames), args.out, fps=fps)
    print(f"video: {path} ({len(frames)} frames at {fps} fps); {time.perf_counter() - began:.1f} s in all")


PERIODIC = np.array(suite.describe("pendulum", "swingup").periodic)


def features(states: np.ndarray) -> np.ndarray:
    """(N, d) states -> (N, d + k): each of the k periodic coordinates (angles, which jump
    from pi to -pi) as its cosine and sine, so that a network sees no jump."""
    angles = states[:, PERIODIC]
    return np.concatenate([np.cos(angles), np.sin(angles), states[:, ~PERIODIC]], axis=1)


class AngleFeatures(VecEnvWrapper):
    """The observations as :func:`features`, the terminal ones included."""

    def __init__(self, venv: sb3.Sb3VecEnv) -> None:
        size = len(PERIODIC) + int(PERIODIC.sum())
        super().__init__(venv, observation_space=gym.spaces.Box(-np.inf, np.inf, (size,), np.float64))

    def reset(self) -> np.ndarray:
        return features(self.venv.reset())

    def step_wait(self) -> tuple:
        observations, rewards, dones, infos = self.venv.step_wait()
        for info in infos:
            if "terminal_observation" in info:
                info["terminal_observation"] = features(info["terminal_observation"][None])[0]
        return features(observations), rewards, dones, infos


class _Random:
    """Uniform random actions, in the shape ``evaluate_policy`` asks a model for."""

    def __init__(self, envs: VecMonitor) -> None:
        self.space, self.rng = envs.action_space, np.random.default_rng(0)

    def predict(self, observation: np.ndarray, *args: object, **kwargs: object) -> tuple[np.ndarray, None]:
        size = (len(observation), *self.space.shape)
        return self.rng.uniform(self.space.low, self.space.high, size).astype(self.space.dtype), None


if __name__ == "__main__":
    main()
