"""The native vector env (tatl_mj.vector): each env's transitions are the single env's, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")
from gymnasium.vector import AutoresetMode  # noqa: E402

import tatl_mj.gym as tatl_gym  # noqa: E402
from tatl_mj import suite, vector  # noqa: E402
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


# --- Contexts per env -------------------------------------------------------------------

SAMPLERS = {  # a law over the keys each task's sweeps vary, and its masses, lengths and gains
    "tatl_mj/CartpoleBalance-v2": {"pole_mass": (0.05, 0.3), "pole_half_length": (0.3, 0.8)},
    "tatl_mj/MountainCarClimb-v2": {"car_mass": (0.8, 1.2), "force": (4.5, 6.0)},
    "tatl_mj/PendulumSwingup-v2": {"mass": (0.5, 1.5), "length": (0.5, 1.5), "gravity": (8.0, 11.0)},
    "tatl_mj/PendulumSwingupTimevarying-v2": {"amplitude": (0.0, 0.75), "mass": (1.0, 1.5)},
    "tatl_mj/PendulumSwingupFlipped-v2": {"gain": (0.5, 2.0), "length": (0.8, 1.2)},
    "tatl_mj/BicycleBalance-v2": {"cg_noise": (0.0, 0.25), "speed": (1.5, 2.778), "tyre_friction": (1.0, 1.4)},
}


def _contexts_of(info, i):
    return {key: float(values[i]) for key, values in info["context"].items()}


def _check_against_singles(env_id, envs, n, seed, actions, task_kwargs, mask_at=None):
    """Steps ``envs`` and n single envs side by side (NEXT_STEP autoreset), each single env given the
    context its vector env shows at every start; asserts bit-equality. Returns the starts seen."""
    singles = [gymnasium.make(env_id, task_kwargs=task_kwargs) for _ in range(n)]
    obs, info = envs.reset(seed=seed)
    first = [e.reset(seed=seed + i, options={"context": _contexts_of(info, i)})[0] for i, e in enumerate(singles)]
    np.testing.assert_array_equal(obs, np.stack(first))
    pending, starts = np.zeros(n, bool), n
    for t, row in enumerate(actions):
        if t == mask_at:  # envs 0 and 2 start again by hand: out of lockstep, each with a new draw
            mask = np.arange(n) % 2 == 0
            _, info = envs.reset(options={"reset_mask": mask})
            for i in np.flatnonzero(mask):
                singles[i].reset(options={"context": _contexts_of(info, i)})
                pending[i], starts = False, starts + 1
        got_obs, got_reward, got_terminated, got_truncated, info = envs.step(row)
        for i, env in enumerate(singles):
            if pending[i]:
                obs_i, reward, ended = env.reset(options={"context": _contexts_of(info, i)})[0], 0.0, (False, False)
                pending[i], starts = False, starts + 1
            else:
                obs_i, reward, *ended, _ = env.step(row[i])
                pending[i] = any(ended)
            np.testing.assert_array_equal(got_obs[i], obs_i, err_msg=f"{env_id} step {t} env {i}")
            assert (got_reward[i], got_terminated[i], got_truncated[i]) == (reward, *ended), f"{env_id} {t} {i}"
    return starts


@pytest.mark.parametrize("mode", ["distinct", "resample"])
@pytest.mark.parametrize("env_id", IDS)
def test_each_env_is_the_single_env_with_its_seed_and_contexts(env_id, mode):
    # Short episodes, so every env autoresets; with a sampler each start draws a new context.
    domain, task = tatl_gym.GYM_IDS[env_id]
    n, seed = 3, 11
    task_kwargs = {"time_limit": 19 * tatl_gym.suite.describe(domain, task).control_timestep}
    sampler = suite.ContextSampler(SAMPLERS[env_id], seed=4)
    generator = np.random.default_rng(9)
    contexts = sampler if mode == "resample" else [sampler.sample(generator) for _ in range(n)]
    envs = _vector(env_id, n, task_kwargs=task_kwargs, contexts=contexts)
    starts = _check_against_singles(env_id, envs, n, seed, _actions(n, 60, seed=3), task_kwargs, mask_at=7)
    assert starts >= 3 * n


@pytest.mark.parametrize(
    "env_id, context",
    [
        ("tatl_mj/PendulumSwingup-v2", {"mass": 2.0, "length": 0.5}),  # written into the batch (write_models)
        ("tatl_mj/PendulumSwingupTimevarying-v2", {"amplitude": 0.1}),  # each step's model, per env
        ("tatl_mj/PendulumSwingupFlipped-v2", {"gain": 2.0}),
        ("tatl_mj/CartpoleBalance-v2", {"pole_mass": 0.5}),  # a model built for it, its fields copied
        ("tatl_mj/BicycleBalance-v2", {"speed": 1.5, "cg_noise": 0.0}),  # task keys: per-simulation arrays
    ],
)
def test_a_context_changes_its_envs_dynamics_alone(env_id, context):
    # Three envs from the same seed with the same actions: the two without a context agree, the
    # one with it does not (its dynamics differ, not its start alone).
    envs = _vector(env_id, 3, contexts=[{}, context, {}])
    obs, _ = envs.reset(seed=[5, 5, 5])
    np.testing.assert_array_equal(obs[0], obs[2])
    row = np.full((3, 1), 0.7, np.float32)
    for _ in range(15):
        obs, *_ = envs.step(row)
    np.testing.assert_array_equal(obs[0], obs[2])
    assert not np.array_equal(obs[0], obs[1])


@pytest.mark.parametrize(
    "contexts, message",
    [
        ([{"mas": 1.0}, {}], r"contexts\[0\]: unknown context key\(s\) \['mas'\]; valid: mass \(kg, 0.1..10\)"),
        ([{}, {"mass": 0.0}], r"contexts\[1\]: context mass must be a number in \[0.1, 10\] kg, got 0.0"),
        ([{}, {"mass": "1"}], r"context mass must be a number in \[0.1, 10\] kg, got '1'"),
        ([{}, {"length": 2.0, "amplitude": 1.0}], "mass 1 must exceed the amplitude 1"),
        ([{}], "contexts must be a list of 2 dicts"),
        ({"mass": 1.0}, "contexts must be a list of 2 dicts"),
        ([{}, 1.0], "a context must be a dict"),
        (suite.ContextSampler({"mass": (0.5, 20.0)}), r"sampler range mass \(0.5, 20.0\) must be \(low, high\) within"),
        (suite.ContextSampler({"gain": (0.5, 1.0)}), r"unknown context key\(s\) \['gain'\] in the sampler"),
    ],
)
def test_bad_contexts_are_refused_in_one_line_before_an_env_is_built(monkeypatch, contexts, message):
    def no_build(*args, **kwargs):
        raise AssertionError("an env was built before the contexts were checked")

    monkeypatch.setattr(tatl_gym.suite, "load", no_build)
    with pytest.raises(ValueError, match=message) as error:
        vector.TatlVectorEnv("pendulum", "swingup_timevarying", num_envs=2, contexts=contexts)
    assert "\n" not in str(error.value)


def test_a_sampled_context_out_of_range_is_refused_when_drawn():
    envs = vector.TatlVectorEnv(
        "pendulum", "swingup", num_envs=2, contexts=suite.ContextSampler(draw=lambda g: {"mass": 50.0})
    )
    with pytest.raises(ValueError, match=r"sampled context: context mass must be a number in \[0.1, 10\]"):
        envs.reset(seed=0)


def test_a_sampler_draws_the_same_contexts_from_the_same_seeds():
    sampler = suite.ContextSampler({"cg_noise": (0.0, 0.25), "speed": (1.5, 2.778)}, seed=3)

    def run(seed):
        envs = _vector("tatl_mj/BicycleBalance-v2", 3, contexts=sampler, task_kwargs={"time_limit": 0.1})
        drawn = [envs.reset(seed=seed)[1]["context"]]
        for _ in range(25):  # ten steps an episode: two more draws each
            drawn.append(envs.step(np.zeros((3, 1), np.float32))[4]["context"])
        return drawn

    first, again, other = run(0), run(0), run(1)
    assert all(a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a) for a, b in zip(first, again))
    assert not np.array_equal(first[0]["speed"], other[0]["speed"])  # reset(seed=...) reseeds the sampler too
    assert len(set(np.concatenate([d["speed"] for d in first]))) == 9  # three draws for each of three envs


def test_context_in_observation_widens_the_space_with_the_values():
    envs = _vector("tatl_mj/PendulumSwingupFlipped-v2", 2, contexts=[{"gain": 0.5}, {}], context_in_observation=True)
    single = gymnasium.make("tatl_mj/PendulumSwingupFlipped-v2", context_in_observation=True)
    names = tatl_gym.suite.context_spec("pendulum", "swingup_flipped").names
    assert names == ("mass", "length", "gravity", "gain")
    assert envs.single_observation_space.shape == single.observation_space.shape == (6,)
    obs, info = envs.reset(seed=0)
    np.testing.assert_array_equal(obs[:, 2:], [[1.0, 1.0, 9.81, 0.5], [1.0, 1.0, 9.81, 1.0]])
    np.testing.assert_array_equal(info["context"]["gain"], [0.5, 1.0])
    single_obs, single_info = single.reset(seed=0, options={"context": {"gain": 0.5}})
    np.testing.assert_array_equal(single_obs, obs[0])
    assert single_info["context"] == {"mass": 1.0, "length": 1.0, "gravity": 9.81, "gain": 0.5}
    assert envs.observation_space.contains(obs) and single.observation_space.contains(single_obs)


def test_write_models_gives_the_time_varying_pendulums_own_models():
    # write_pendulum's arrays and the batch's set_const against set_pendulum's scalars and mj_setConst,
    # derived fields included, at several steps of the schedule.
    context = {"amplitude": 0.3, "mass": 1.2}
    envs = vector.TatlVectorEnv("pendulum", "swingup_timevarying", num_envs=2, contexts=[context, {"length": 2.0}])
    envs.reset(seed=0)
    values = tatl_gym.suite.check_context("pendulum", "swingup_timevarying", context)
    kwargs = tatl_gym.suite.task_kwargs_with_context("pendulum", "swingup_timevarying", {}, values)
    env = tatl_gym.suite.load("pendulum", "swingup_timevarying", task_kwargs=kwargs)
    for step in (0, 1, 37, 150):
        envs._contexts.write_models(np.array([0]), np.array([step]))
        env.task.model_for_step(env.physics, step)
        model = envs._batch.get_model(0)
        for name in sorted(envs._contexts.live) + ["body_subtreemass", "dof_invweight0", "actuator_acc0"]:
            mine, theirs = vector.model_field(model, name), vector.model_field(env.physics.model.ptr, name)
            np.testing.assert_array_equal(mine, theirs, err_msg=f"{name} at step {step}")
