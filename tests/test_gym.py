"""Gymnasium ids for every physics task: registration, env_checker, and agreement with the dm_env task."""

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")
from gymnasium.utils.env_checker import check_env  # noqa: E402

import tatl_mj.gym as tatl_gym  # noqa: E402
from tatl_mj import suite  # noqa: E402

IDS = sorted(tatl_gym.GYM_IDS)


def test_every_physics_task_has_an_id():
    assert set(tatl_gym.GYM_IDS.values()) == {(d, t) for d, t in suite.ALL_TASKS if d != "gridworld"}
    assert "tatl_mj/BicycleBalance-v0" in IDS and "tatl_mj/PendulumSwingupFlipped-v0" in IDS
    assert all(i in gymnasium.registry for i in IDS)


@pytest.mark.parametrize("env_id", IDS)
def test_passes_gymnasium_env_checker(env_id):
    env = gymnasium.make(env_id, render_mode="rgb_array", width=64, height=48)
    check_env(env.unwrapped)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (48, 64, 3) and frame.dtype == np.uint8
    env.close()


def test_steps_match_the_dm_env_task_and_end_as_it_does():
    # Cart-pole pushed right at full force: the same rewards and states as suite.load, and the
    # toppled pole is a terminal state (terminated, not truncated).
    env = gymnasium.make("tatl_mj/CartpoleBalance-v0")
    observation, _ = env.reset(seed=3)
    dm = suite.load("cartpole", "balance", task_kwargs={"random": 3})
    timestep = dm.reset()
    np.testing.assert_array_equal(observation, timestep.observation["state"])
    high = env.action_space.high
    assert high[0] == 20.0 and env.action_space.low[0] == -20.0
    for _ in range(200):
        observation, reward, terminated, truncated, _ = env.step(high)
        timestep = dm.step(high)
        np.testing.assert_array_equal(observation, timestep.observation["state"])
        assert reward == timestep.reward
        if terminated or truncated:
            break
    assert terminated and not truncated and timestep.last() and timestep.discount == 0


def test_time_limit_truncates():
    env = gymnasium.make("tatl_mj/PendulumSwingup-v0", task_kwargs={"time_limit": 0.5})
    env.reset(seed=0)
    ends = [env.step(np.zeros(1))[2:4] for _ in range(10)]  # 0.05 s steps
    assert ends[-1] == (False, True) and all(e == (False, False) for e in ends[:-1])


def test_bad_arguments_name_the_valid_choices():
    with pytest.raises(ValueError, match="render_mode must be None or one of"):
        tatl_gym.TatlEnv("cartpole", "balance", render_mode="human")
    with pytest.raises(ValueError, match="valid: .*cartpole/balance"):
        tatl_gym.TatlEnv("gridworld", "plain")
