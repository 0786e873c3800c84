"""The native vector env (tatl_mj.vector): each env's transitions are the single env's, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")
from gymnasium.vector import AutoresetMode  # noqa: E402

import tatl_mj.gym as tatl_gym  # noqa: E402
from tatl_mj import vector  # noqa: E402
from tatl_mj.suite import cartpole  # noqa: E402

IDS = sorted(tatl_gym.GYM_IDS)


def _vector(env_id, n, **kwargs):
    return gymnasium.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", **kwargs)


def _replay(env_id, n, seed, actions, task_kwargs=None, resets=(), same_step=False):
    """What n single envs (gym.make) give for ``actions`` (T, n, 1), reset with seed + i and
    autoreset as the vector env does; ``resets``: {step: mask} of envs reset before that step."""
    singles = [gymnasium.make(env_id, task_kwargs=task_kwargs) for _ in range(n)]
    first = np.stack([e.reset(seed=seed + i)[0] for i, e in enumerate(singles)])
    pending = np.zeros(n, bool)
    out = []
    for t, row in enumerate(actions):
        obs, reward = np.zeros_like(first), np.zeros(n)
        terminated, truncated, final = np.zeros(n, bool), np.zeros(n, bool), [None] * n
        for i, env in enumerate(singles):
            if t in resets and resets[t][i]:
                env.reset()
                pending[i] = False
            if pending[i]:  # NEXT_STEP: the step after an episode's end resets it
                obs[i] = env.reset()[0]
                pending[i] = False
                continue
            obs[i], reward[i], terminated[i], truncated[i], _ = env.step(row[i])
            if terminated[i] or truncated[i]:
                if same_step:
                    final[i], obs[i] = obs[i].copy(), env.reset()[0]
                else:
                    pending[i] = True
        out.append((obs, reward, terminated, truncated, final))
    return first, out


def _actions(n, steps, seed=0):
    # Beyond the space too (clipped), and exactly representable in float32.
    return np.random.default_rng(seed).uniform(-1.3, 1.3, size=(steps, n, 1)).astype(np.float32)


@pytest.mark.parametrize("env_id", IDS)
def test_each_env_is_the_single_env_with_its_seed(env_id):
    # Short episodes (a time limit of 37 steps), so that every env ends and autoresets several
    # times; envs 0 and 2 reset by hand at step 23, so they leave lockstep with the others.
    domain, task = tatl_gym.GYM_IDS[env_id]
    n, steps, seed = 5, 130, 7
    task_kwargs = {"time_limit": 37 * tatl_gym.suite.describe(domain, task).control_timestep}
    actions = _actions(n, steps)
    resets = {23: np.array([True, False, True, False, False])}
    first, expected = _replay(env_id, n, seed, actions, task_kwargs, resets)
    envs = _vector(env_id, n, task_kwargs=task_kwargs)
    obs, _ = envs.reset(seed=seed)
    np.testing.assert_array_equal(obs, first)
    ends = 0
    for t, row in enumerate(actions):
        if t in resets:
            envs.reset(options={"reset_mask": resets[t]})
        got = envs.step(row)
        for k in range(4):
            np.testing.assert_array_equal(got[k], expected[t][k], err_msg=f"{env_id} step {t} field {k}")
        ends += int((got[2] | got[3]).sum())
    assert ends >= 2 * n  # every env ended and restarted, some out of lockstep


@pytest.mark.parametrize("env_id", ["tatl_mj/BicycleBalance-v2", "tatl_mj/PendulumSwingupTimevarying-v2"])
def test_same_step_autoreset_gives_the_final_observation_in_info(env_id):
    n, steps, seed = 4, 90, 3
    domain, task = tatl_gym.GYM_IDS[env_id]
    task_kwargs = {"time_limit": 29 * tatl_gym.suite.describe(domain, task).control_timestep}
    actions = _actions(n, steps, seed=1)
    first, expected = _replay(env_id, n, seed, actions, task_kwargs, same_step=True)
    envs = _vector(env_id, n, task_kwargs=task_kwargs, autoreset_mode=AutoresetMode.SAME_STEP)
    assert envs.metadata["autoreset_mode"] is AutoresetMode.SAME_STEP
    np.testing.assert_array_equal(envs.reset(seed=seed)[0], first)
    for t, row in enumerate(actions):
        obs, reward, terminated, truncated, info = envs.step(row)
        e_obs, e_reward, e_terminated, e_truncated, e_final = expected[t]
        np.testing.assert_array_equal(obs, e_obs)
        np.testing.assert_array_equal(reward, e_reward)
        np.testing.assert_array_equal(terminated | truncated, e_terminated | e_truncated)
        done = terminated | truncated
        if done.any():
            np.testing.assert_array_equal(info["_final_obs"], done)
            for i in np.flatnonzero(done):
                np.testing.assert_array_equal(info["final_obs"][i], e_final[i])
        else:
            assert "final_obs" not in info


def test_a_diverged_simulation_ends_as_in_the_single_env(monkeypatch):
    # A start moving at 2e10 m/s makes MuJoCo warn on the first step: terminated, reward 0,
    # the last finite state and dm_control's message, in both.
    start = cartpole.Task.start_configurations

    def fast_start(self, physics, n):
        qpos, qvel = start(self, physics, n)
        return qpos, qvel + 2e10

    monkeypatch.setattr(cartpole.Task, "start_configurations", fast_start)
    single = gymnasium.make("tatl_mj/CartpoleBalance-v2")
    first = single.reset(seed=0)[0]
    s_obs, s_reward, s_terminated, s_truncated, s_info = single.step(np.zeros(1, np.float32))
    envs = _vector("tatl_mj/CartpoleBalance-v2", 2)
    np.testing.assert_array_equal(envs.reset(seed=0)[0][0], first)
    obs, reward, terminated, truncated, info = envs.step(np.zeros((2, 1), np.float32))
    assert s_terminated and terminated.all() and not truncated.any() and s_reward == 0 == reward[0]
    np.testing.assert_array_equal(obs[0], s_obs)
    assert info["diverged"][0] == s_info["diverged"] and info["_diverged"].all()
    assert "Warning(s) raised: mjWARN_BADQVEL" in s_info["diverged"]


def test_make_vec_picks_the_native_env_and_its_spaces_are_the_single_envs():
    envs = gymnasium.make_vec("tatl_mj/PendulumSwingup-v2", num_envs=3)  # the default, registered mode
    assert isinstance(envs.unwrapped, vector.TatlVectorEnv)
    single = gymnasium.make("tatl_mj/PendulumSwingup-v2")
    assert envs.single_action_space == single.action_space and envs.action_space.shape == (3, 1)
    assert envs.single_observation_space == single.observation_space
    assert envs.action_space.dtype == np.float32 and envs.observation_space.dtype == np.float64
    assert envs.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    assert envs.unwrapped.max_episode_steps == single.spec.max_episode_steps == 200
    assert _vector("tatl_mj/PendulumSwingup-v2", 2, max_episode_steps=50).unwrapped.max_episode_steps == 50


def test_seeds_are_per_env_and_a_later_reset_goes_on():
    envs = _vector("tatl_mj/BicycleBalance-v2", 3)
    by_int = envs.reset(seed=5)[0]
    again = envs.reset()[0]  # the random states go on: new starts
    assert not np.array_equal(by_int, again)
    by_list = envs.reset(seed=[5, 6, 7])[0]
    np.testing.assert_array_equal(by_int, by_list)
    singles = [gymnasium.make("tatl_mj/BicycleBalance-v2") for _ in range(3)]
    np.testing.assert_array_equal(by_int, np.stack([e.reset(seed=5 + i)[0] for i, e in enumerate(singles)]))
    assert len({tuple(row) for row in by_int}) == 3  # each env its own start


def test_render_draws_each_env():
    envs = _vector("tatl_mj/PendulumSwingupTimevarying-v2", 2, render_mode="rgb_array", width=32, height=24)
    envs.reset(seed=0)
    for _ in range(30):
        envs.step(np.ones((2, 1), np.float32))
    frames = envs.render()
    assert len(frames) == 2 and frames[0].shape == (24, 32, 3) and frames[0].std() > 5
    single = gymnasium.make("tatl_mj/PendulumSwingupTimevarying-v2", render_mode="rgb_array", width=32, height=24)
    single.reset(seed=1)
    for _ in range(30):
        single.step(np.ones(1, np.float32))
    single.unwrapped.dm_environment.physics.forward()  # poses of the state itself, as the vector env draws
    np.testing.assert_array_equal(frames[1], single.render())  # the same state and rod length
    envs.close()


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"num_envs": 0}, "num_envs must be an integer >= 1"),
        ({"autoreset_mode": "disabled"}, r"autoreset_mode must be one of \['NextStep', 'SameStep'\]"),
        ({"max_episode_steps": 0}, "max_episode_steps must be an integer >= 1"),
        ({"task_kwargs": {"random": np.random.RandomState(0)}}, r"task_kwargs\['random'\] must be None or an integer"),
        ({"render_mode": "human"}, "render_mode must be None or one of"),
    ],
)
def test_bad_arguments_name_the_field(kwargs, message):
    with pytest.raises(ValueError, match=message):
        vector.TatlVectorEnv("pendulum", "swingup", **{"num_envs": 2, **kwargs})


def test_bad_calls_name_what_is_wrong():
    envs = vector.TatlVectorEnv("cartpole", "balance", num_envs=2)
    with pytest.raises(ValueError, match="call reset"):
        envs.step(np.zeros((2, 1), np.float32))
    envs.reset(seed=0)
    with pytest.raises(ValueError, match=r"action must have shape \(2, 1\)"):
        envs.step(np.zeros(2, np.float32))
    with pytest.raises(ValueError, match="seed must be None, an integer"):
        envs.reset(seed=[1])
    with pytest.raises(ValueError, match="reset_mask"):
        envs.reset(options={"reset_mask": np.zeros(2, bool)})
    with pytest.raises(ValueError, match=r"unknown reset options \['other'\]"):
        envs.reset(options={"other": 1})
    with pytest.raises(ValueError, match="unknown physics task gridworld/plain"):
        vector.TatlVectorEnv("gridworld", "plain")


def test_step_models_made_beyond_those_made_ahead_are_the_same(monkeypatch):
    # The time-varying pendulum's models of steps past StepModels.AHEAD are made while
    # stepping (their tables grown); the envs stay the single envs.
    monkeypatch.setattr(vector.StepModels, "AHEAD", 3)
    env_id, n, seed = "tatl_mj/PendulumSwingupTimevarying-v2", 3, 4
    actions = _actions(n, 60, seed=5)
    first, expected = _replay(env_id, n, seed, actions, {"time_limit": 2.5})  # 50 steps
    envs = _vector(env_id, n, task_kwargs={"time_limit": 2.5})
    assert envs.unwrapped._schedule.known == 3
    np.testing.assert_array_equal(envs.reset(seed=seed)[0], first)
    for t, row in enumerate(actions):
        got = envs.step(row)
        for k in range(4):
            np.testing.assert_array_equal(got[k], expected[t][k])
    assert envs.unwrapped._schedule.known == 50
