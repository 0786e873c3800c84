"""Gymnasium ids for every physics task: registration, env_checker, and agreement with the dm_env task."""

import warnings

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")
from gymnasium.utils.env_checker import check_env  # noqa: E402

import tatl_mj.gym as tatl_gym  # noqa: E402
from tatl_mj import suite  # noqa: E402

IDS = sorted(tatl_gym.GYM_IDS)


def test_every_physics_task_has_an_id():
    assert set(tatl_gym.GYM_IDS.values()) == {(d, t) for d, t in suite.ALL_TASKS if d != "gridworld"}
    assert "tatl_mj/BicycleBalance-v2" in IDS and "tatl_mj/PendulumSwingupFlipped-v2" in IDS
    assert all(i in gymnasium.registry for i in IDS)


@pytest.mark.parametrize("env_id", IDS)
def test_passes_gymnasium_env_checker(env_id):
    env = gymnasium.make(env_id, render_mode="rgb_array", width=64, height=48)
    check_env(env.unwrapped)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (48, 64, 3) and frame.dtype == np.uint8
    env.close()


@pytest.mark.parametrize("env_id", IDS)
def test_every_id_runs_without_a_warning(env_id):
    # gymnasium.make (its PassiveEnvChecker included), reset, step, render and check_env, with
    # any warning an error: the render modes are declared where make reads them, the spaces are
    # bounded and the action space normalised.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gymnasium.make(env_id, render_mode="rgb_array", width=32, height=24)
        env.reset(seed=0)
        env.step(env.action_space.sample())
        assert env.render().shape == (24, 32, 3)
        check_env(env.unwrapped)
        env.close()
        plain = gymnasium.make(env_id)  # check_env then makes one per declared render mode
        check_env(plain.unwrapped, skip_render_check=False)
        plain.close()


@pytest.mark.parametrize(
    "action, message",
    [
        (
            np.zeros(3),
            r"action must have shape \(1,\) \(the action space Box\(-1.0, 1.0, \(1,\), float32\)\), got shape \(3,\)",
        ),
        (0.5, r"must have shape \(1,\) \(the action space Box.*got shape \(\)"),
        (np.zeros((1, 1)), r"must have shape \(1,\) \(the action space Box.*got shape \(1, 1\)"),
        (np.array([np.nan]), r"action \[nan\] is not finite \(the action space is Box"),
        ("left", r"action must be an array in the action space Box"),
    ],
    ids=["size-3", "scalar", "batched", "nan", "text"],
)
def test_bad_actions_raise_value_errors_naming_the_action_space(action, message):
    env = gymnasium.make("tatl_mj/CartpoleBalance-v2")
    env.reset(seed=0)
    with pytest.raises(ValueError, match=message):
        env.step(action)
    env.step(np.array([1.0]))  # the bounds themselves are in the space
    env.step(np.float32([-1.0]))


def test_actions_are_fractions_of_the_actuator_limit_unless_asked_otherwise():
    env = gymnasium.make("tatl_mj/CartpoleBalance-v2")
    assert env.action_space.low[0] == -1.0 and env.action_space.high[0] == 1.0
    assert env.unwrapped.actuator_limit[0] == 20.0
    raw = gymnasium.make("tatl_mj/CartpoleBalance-v2", normalize_actions=False)
    assert raw.action_space.low[0] == -20.0 and raw.action_space.high[0] == 20.0
    for e in (env, raw):
        e.reset(seed=1)
    np.testing.assert_array_equal(env.step(np.array([0.5]))[0], raw.step(np.array([10.0]))[0])
    # Beyond the space is clipped to it, as the actuator would.
    for e in (env, raw):
        e.reset(seed=2)
    np.testing.assert_array_equal(raw.step(np.array([25.0]))[0], env.step(np.array([1.0]))[0])


def test_renders_from_the_camera_the_domain_declares():
    from tatl_mj.suite import bicycle

    env = gymnasium.make("tatl_mj/BicycleBalance-v2", render_mode="rgb_array", width=32, height=24)
    assert bicycle.CAMERA == "behind" and env.unwrapped._camera == "behind"
    side = gymnasium.make("tatl_mj/BicycleBalance-v2", render_mode="rgb_array", width=32, height=24, camera="tracking")
    for e in (env, side):
        e.reset(seed=0)
    assert np.any(env.render() != side.render())


def test_steps_match_the_dm_env_task_and_end_as_it_does():
    # Cart-pole pushed right at full force: the same rewards and states as suite.load, and the
    # toppled pole is a terminal state (terminated, not truncated).
    env = gymnasium.make("tatl_mj/CartpoleBalance-v2")
    observation, _ = env.reset(seed=3)
    dm = suite.load("cartpole", "balance", task_kwargs={"random": 3})
    timestep = dm.reset()
    np.testing.assert_array_equal(observation, timestep.observation["state"])
    high = env.action_space.high
    assert high[0] == 1.0 and env.action_space.low[0] == -1.0  # fractions of the 20 N limit
    for _ in range(200):
        observation, reward, terminated, truncated, _ = env.step(high)
        timestep = dm.step(20.0 * high)
        np.testing.assert_array_equal(observation, timestep.observation["state"])
        assert reward == timestep.reward
        if terminated or truncated:
            break
    assert terminated and not truncated and timestep.last() and timestep.discount == 0


def test_time_limit_truncates():
    env = gymnasium.make("tatl_mj/PendulumSwingup-v2", task_kwargs={"time_limit": 0.5})
    env.reset(seed=0)
    ends = [env.step(np.zeros(1))[2:4] for _ in range(10)]  # 0.05 s steps
    assert ends[-1] == (False, True) and all(e == (False, False) for e in ends[:-1])


def test_bad_arguments_name_the_valid_choices():
    with pytest.raises(ValueError, match="render_mode must be None or one of"):
        tatl_gym.TatlEnv("cartpole", "balance", render_mode="human")
    with pytest.raises(ValueError, match="valid: .*cartpole/balance"):
        tatl_gym.TatlEnv("gridworld", "plain")


@pytest.mark.parametrize("env_id", IDS)
def test_time_limit_is_max_episode_steps_and_follows_a_time_limit_override(env_id):
    domain, task = tatl_gym.GYM_IDS[env_id]
    env = gymnasium.make(env_id)
    assert env.spec.max_episode_steps == env.unwrapped.max_episode_steps
    assert any(isinstance(w, gymnasium.wrappers.TimeLimit) for w in _wrappers(env))
    step = suite.describe(domain, task).control_timestep
    assert env.spec.max_episode_steps == pytest.approx(suite.time_limit(domain, task) / step, abs=1)
    # Overridden, it is the step at which the task's own episode ends (dm_control's count).
    for seconds in (7 * step, 23 * step):
        short = gymnasium.make(env_id, task_kwargs={"time_limit": seconds})
        dm = suite.load(domain, task, task_kwargs={"time_limit": seconds, "random": 0})
        dm.reset()
        length = next(n for n in range(1, 100) if dm.step(np.zeros(1)).last())
        assert short.spec.max_episode_steps == length
        short.reset(seed=0)
        ends = [short.step(np.zeros(1, np.float32))[3] for _ in range(length)]
        assert ends == [False] * (length - 1) + [True]
    assert gymnasium.make("tatl_mj/PendulumSwingup-v2").spec.max_episode_steps == 200  # 10 s of 0.05 s


def _wrappers(env):
    while isinstance(env, gymnasium.Wrapper):
        yield env
        env = env.env


def test_a_longer_time_limit_is_not_cut_at_the_default():
    env = gymnasium.make("tatl_mj/PendulumSwingup-v2", task_kwargs={"time_limit": 15.0})
    env.reset(seed=0)
    ends = [env.step(np.zeros(1, np.float32))[2:4] for _ in range(300)]
    assert ends[-1] == (False, True) and all(e == (False, False) for e in ends[:-1])


def test_action_spaces_are_float32():
    for env_id in IDS:
        env = gymnasium.make(env_id)
        assert env.action_space.dtype == np.float32 and env.observation_space.dtype == np.float64
        raw = gymnasium.make(env_id, normalize_actions=False)
        assert raw.action_space.dtype == np.float32
        assert raw.action_space.high[0] == env.unwrapped.actuator_limit[0]  # exact in float32


def test_v1_still_works_and_names_v2():
    old = "tatl_mj/PendulumSwingup-v1"
    # Ours names what changed; Gymnasium's own registry adds that a newer version exists.
    with (
        pytest.warns(DeprecationWarning, match=r"use tatl_mj/PendulumSwingup-v2, whose actions are float32"),
        pytest.warns(DeprecationWarning, match=r"PendulumSwingup-v1 is out of date"),
    ):
        env = gymnasium.make(old)
    assert env.action_space.dtype == np.float64 and env.spec.max_episode_steps is None
    new = gymnasium.make("tatl_mj/PendulumSwingup-v2")
    # The same dynamics: an interface version, not a dynamics version.
    first = env.reset(seed=4)[0], new.reset(seed=4)[0]
    np.testing.assert_array_equal(*first)
    for a in np.linspace(-1, 1, 20, dtype=np.float32):  # the same numbers in either dtype
        np.testing.assert_array_equal(env.step(np.array([a], np.float64))[0], new.step(np.array([a]))[0])


@pytest.mark.parametrize("env_id", IDS)
def test_passes_stable_baselines3_env_checker_without_a_warning(env_id):
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gymnasium.make(env_id)
        sb3_checker.check_env(env)
        sb3_checker.check_env(env.unwrapped)


def test_a_reset_context_rebuilds_the_task_for_this_and_later_episodes():
    env = gymnasium.make("tatl_mj/BicycleBalance-v2", task_kwargs={"time_limit": 0.05})
    _, info = env.reset(seed=0)
    assert "context" not in info  # none given
    _, info = env.reset(seed=0, options={"context": {"speed": 1.5, "rider_mass": 50.0}})
    assert info["context"]["speed"] == 1.5 and info["context"]["cg_noise"] == 0.02  # the rest: task_kwargs'
    task, physics = env.unwrapped.dm_environment.task, env.unwrapped.dm_environment.physics
    assert task.speed == 1.5 and physics.named.model.body_mass["rider"] == 50.0
    for _ in range(5):  # past the episode's end: the next one keeps the context
        *_, terminated, truncated, info = env.step(np.zeros(1, np.float32))
    assert truncated and info["context"]["speed"] == 1.5
    env.reset()
    assert env.unwrapped.dm_environment.task.speed == 1.5
    # The random state goes on across the rebuild: seeded starts equal those of an env built with the context.
    built = gymnasium.make(
        "tatl_mj/BicycleBalance-v2", task_kwargs={"speed": 1.5, "params": suite.bicycle.BicycleParams(rider_mass=50.0)}
    )
    np.testing.assert_array_equal(env.reset(seed=4)[0], built.reset(seed=4)[0])
    for _ in range(3):
        np.testing.assert_array_equal(env.step(np.ones(1, np.float32))[0], built.step(np.ones(1, np.float32))[0])


@pytest.mark.parametrize(
    "options, message",
    [
        ({"context": {"speeed": 1.0}}, r"reset context: unknown context key\(s\) \['speeed'\]; valid: speed \(m/s"),
        ({"context": {"cg_noise": 0.5}}, r"context cg_noise must be a number in \[0, 0.25\] m, got 0.5"),
        ({"contexts": {}}, r"unknown reset options \['contexts'\]; valid: \['context'\]"),
    ],
)
def test_a_bad_reset_context_is_refused_in_one_line_and_the_env_goes_on(options, message):
    env = gymnasium.make("tatl_mj/BicycleBalance-v2")
    env.reset(seed=0)
    with pytest.raises(ValueError, match=message) as error:
        env.reset(options=options)
    assert "\n" not in str(error.value)
    env.step(np.zeros(1, np.float32))  # the env as it was
    assert env.unwrapped.context["speed"] == suite.bicycle.DEFAULT_SPEED
