"""The Stable-Baselines3 adapter (tatl_mj.sb3): SB3's DummyVecEnv conventions over the native vector env."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
import gymnasium  # noqa: E402
from stable_baselines3.common.vec_env import DummyVecEnv  # noqa: E402

import tatl_mj.gym as tatl_gym  # noqa: E402
from tatl_mj import sb3  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize(
    "env_id", ["tatl_mj/PendulumSwingupTimevarying-v2", "tatl_mj/BicycleBalance-v2", "tatl_mj/CartpoleBalance-v2"]
)
def test_adapter_gives_what_dummy_vec_env_gives(env_id):
    # Short episodes, so that time limits (TimeLimit.truncated) and terminal states both end some.
    domain, task = tatl_gym.GYM_IDS[env_id]
    task_kwargs = {"time_limit": 31 * tatl_gym.suite.describe(domain, task).control_timestep}
    n = 4
    ours = sb3.vec_env(env_id, n, task_kwargs=task_kwargs)
    theirs = DummyVecEnv([lambda: gymnasium.make(env_id, task_kwargs=task_kwargs) for _ in range(n)])
    assert ours.seed(11) == theirs.seed(11) == [11, 12, 13, 14]
    np.testing.assert_array_equal(ours.reset(), theirs.reset())
    actions = np.random.default_rng(2).uniform(-1, 1, size=(100, n, 1)).astype(np.float32)
    truncations = ends = 0
    for row in actions:
        got, expected = ours.step(row), theirs.step(row)
        for k in range(3):  # observations, rewards (float32), dones
            np.testing.assert_array_equal(got[k], expected[k])
            assert got[k].dtype == expected[k].dtype
        for mine, theirs_info in zip(got[3], expected[3]):
            assert mine["TimeLimit.truncated"] == theirs_info["TimeLimit.truncated"]
            truncations += mine["TimeLimit.truncated"]
            assert ("terminal_observation" in mine) == ("terminal_observation" in theirs_info)
            if "terminal_observation" in mine:
                ends += 1
                np.testing.assert_array_equal(mine["terminal_observation"], theirs_info["terminal_observation"])
    assert ends >= n and truncations >= 1  # every env ended, some by the time limit


def test_sac_learns_on_it_and_the_adapter_refuses_a_next_step_vector_env():
    from stable_baselines3 import SAC
    from stable_baselines3.common.vec_env import VecMonitor

    envs = VecMonitor(sb3.vec_env("tatl_mj/PendulumSwingup-v2", 2, task_kwargs={"time_limit": 1.0}))
    model = SAC("MlpPolicy", envs, learning_starts=50, batch_size=32, policy_kwargs={"net_arch": [16]}, seed=0)
    model.learn(120)
    assert model.num_timesteps == 120 and model.replay_buffer.size() == 60  # 2 transitions a step
    assert envs.get_attr("render_mode") == [None, None] and envs.env_is_wrapped(object) == [False, False]
    with pytest.raises(ValueError, match="SAME_STEP"):
        sb3.Sb3VecEnv(gymnasium.make_vec("tatl_mj/PendulumSwingup-v2", num_envs=2))


def test_the_deep_rl_example_runs_headless(tmp_path):
    # scripts/sac_pendulum.py at a tiny budget, MUJOCO_GL unset and no display, warnings as errors:
    # trains, evaluates and writes a video from the same process.
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY")}
    env["PYTHONPATH"] = str(REPO)
    out = tmp_path / "sac.mp4"
    done = subprocess.run(
        [sys.executable, "scripts/sac_pendulum.py", "--steps", "200", "--envs", "2", "--episodes", "2"]
        + ["--video-seconds", "1", "--out", str(out)],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert "Traceback" not in done.stderr and "Warning" not in done.stderr, done.stderr[-3000:]
    assert "trained 200 steps" in done.stdout and "video:" in done.stdout, done.stdout
    assert out.stat().st_size > 1000


def test_adapter_passes_contexts_through_to_each_env():
    # Per-env contexts: the adapter's envs are DummyVecEnv's single envs reset with those contexts,
    # through SB3's same-step autoresets (each single env keeps its context), bit for bit.
    env_id, n = "tatl_mj/PendulumSwingupFlipped-v2", 3
    task_kwargs = {"time_limit": 1.0}  # 20 steps
    contexts = [{"gain": 0.5}, {"gain": 2.0, "mass": 1.3}, {}]
    ours = sb3.vec_env(env_id, n, task_kwargs=task_kwargs, contexts=contexts, context_in_observation=True)
    theirs = DummyVecEnv(
        [lambda: gymnasium.make(env_id, task_kwargs=task_kwargs, context_in_observation=True) for _ in range(n)]
    )
    theirs.set_options([{"context": c} for c in contexts])
    ours.seed(3), theirs.seed(3)
    np.testing.assert_array_equal(ours.reset(), theirs.reset())
    assert ours.observation_space.shape == (6,) and ours.reset_infos[1]["context"]["gain"] == 2.0
    for row in np.random.default_rng(0).uniform(-1, 1, size=(45, n, 1)).astype(np.float32):
        got, expected = ours.step(row), theirs.step(row)
        for k in range(3):
            np.testing.assert_array_equal(got[k], expected[k])
        assert [info["context"]["gain"] for info in got[3]] == [0.5, 2.0, 1.0]
    # A sampler passes through too.
    sampled = sb3.vec_env(env_id, 2, contexts=tatl_gym.suite.ContextSampler({"gain": (0.5, 2.0)}, seed=1))
    sampled.reset()
    gains = [info["context"]["gain"] for info in sampled.reset_infos]
    assert len(set(gains)) == 2 and all(0.5 <= g <= 2.0 for g in gains)
