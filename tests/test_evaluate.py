"""`tatl evaluate` (run/scoring.py, cli/evaluate.py) and its score panels (report/scores.py): known answers.

- a zero-action policy scores the return of zero torque, stepped directly in the suite's env
  from the same evaluation starts (the same at every gain: zero torque feels no gain);
- a built-in method's learned policy, scored this way, gives its record's final and random
  returns exactly;
- a sweep gives one row per condition and seed; bad input is refused in one line before any work;
- an SB3 model's actions reach the target as the Gymnasium id applies them.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, TINY

from tatl_mj import suite
from tatl_mj.cli import main as tatl
from tatl_mj.experiments import spec as spec_mod
from tatl_mj.experiments.run import determinism, scoring

SWEEP = ROOT / "tasks" / "sweeps" / "ip_to_flipped_ip_gain.toml"
PRESET = {
    **TINY,
    "reference_return": -1000,  # above random over 40 steps
    "seeds": 2,
    "first_seed": 100,
}

POLICIES = """
import numpy as np

seen = []

def zero(states):
    return np.zeros((len(states), 1))

def watch(states):
    seen.append(np.array(states))
    return np.zeros((len(states), 1))
"""


def write_sweep(folder: Path, preset: dict = PRESET, iterations: int = 5) -> Path:
    """The gain sweep with a tiny preset (few FQI iterations) in place of its own."""
    text = SWEEP.read_text().split("[presets.smoke]")[0].replace("iterations = 100", f"iterations = {iterations}")
    text += "[presets.tiny]\n" + "\n".join(f"{k} = {json.dumps(v)}" for k, v in preset.items()) + "\n"
    path = folder / "gain_sweep.toml"
    path.write_text(text)
    return path


@pytest.fixture
def policies(tmp_path, monkeypatch):
    (tmp_path / "my_policies.py").write_text(POLICIES)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "my_policies"
    sys.modules.pop("my_policies", None)


def zero_torque_returns(condition, preset, seed: int) -> np.ndarray:
    """Zero torque from the evaluation starts of ``seed``, stepped in the suite's own env."""
    target = condition.target
    eval_seed = determinism.derive_seed(seed, condition.stream_name, "evaluation")
    drawn = suite.load(target.domain, target.task, task_kwargs={**target.task_kwargs, "random": eval_seed})
    qpos, qvel = drawn.task.start_configurations(drawn.physics, preset.evaluation_episodes)
    env = suite.load(target.domain, target.task, task_kwargs=target.task_kwargs)
    returns = []
    for q, v in zip(qpos, qvel):
        env.reset()
        with env.physics.reset_context():
            env.physics.data.qpos[:] = q
            env.physics.data.qvel[:] = v
        total = 0.0
        for _ in range(preset.evaluation_steps):
            step = env.step(np.zeros(1))
            total += step.reward
            if step.last():
                break
        returns.append(total)
    return np.array(returns)


def test_zero_action_policy_scores_its_known_return_one_row_per_condition_and_seed(tmp_path, policies, capsys):
    spec_path, out = write_sweep(tmp_path), tmp_path / "zero"
    assert (
        tatl(["evaluate", str(spec_path), "--policy", f"{policies}:zero", "--preset", "tiny", "--out", str(out)]) == 0
    )
    scores = json.loads((out / scoring.SCORES).read_text())
    spec = spec_mod.load_spec(spec_path)
    preset = spec.preset("tiny")
    conditions = spec_mod.conditions(spec)
    rows = scores["rows"]
    assert [(r["experiment"], r["seed"]) for r in rows] == [(c.name, s) for c in conditions for s in (100, 101)]
    for row, (condition, seed) in zip(rows, [(c, s) for c in conditions for s in (100, 101)]):
        expected = zero_torque_returns(condition, preset, seed)
        np.testing.assert_allclose(row["returns"], expected, rtol=1e-12)
        assert row["normalised"] == pytest.approx(
            (row["mean_return"] - row["random_return"]) / (row["reference_return"] - row["random_return"])
        )
    # Zero torque feels no gain: every condition's returns are one seed's.
    assert rows[0]["returns"] == rows[2]["returns"] == rows[4]["returns"]
    manifest = json.loads((out / scoring.MANIFEST).read_text())
    assert manifest["policy"]["path"] == f"{policies}:zero" and len(manifest["policy"]["module_sha256"]) == 64
    assert manifest["spec_hash"] == spec_mod.content_hash(spec, "tiny") and manifest["seeds"] == [100, 101]
    table = (out / scoring.TABLE).read_text().splitlines()
    assert table[0].startswith("experiment,condition,seed") and len(table) == 1 + 6 and ",gain=0.5,100," in table[1]


def test_a_rerun_resumes_and_another_policy_is_refused(tmp_path, policies, capsys):
    spec_path, out = write_sweep(tmp_path), tmp_path / "zero"
    argv = ["evaluate", str(spec_path), "--policy", f"{policies}:zero", "--preset", "tiny", "--seeds", "1"]
    assert tatl([*argv, "--out", str(out)]) == 0
    unit = next((out / scoring.UNITS).rglob("*.json"))
    written = unit.stat().st_mtime_ns
    capsys.readouterr()
    assert tatl([*argv, "--out", str(out)]) == 0
    assert unit.stat().st_mtime_ns == written and "seed 100: normalised" not in capsys.readouterr().out
    other = ["evaluate", str(spec_path), "--policy", f"{policies}:watch", "--preset", "tiny", "--out", str(out)]
    assert tatl(other) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "holds another evaluation" in err


@pytest.mark.parametrize(
    ("policy", "preset", "message"),
    [
        ("no_colon_here", "tiny", "give module:function or a Stable-Baselines3 model file"),
        ("missing_model.zip", "tiny", "missing_model.zip: no such file"),
        ("{policies}:zero", "smoke", "unknown preset 'smoke'"),
        ("{policies}:zero", "bare", "presets.bare has no reference_return"),
        ("{policies}:nothing", "tiny", "has no attribute 'nothing'"),
    ],
)
def test_bad_input_is_refused_in_one_line_before_any_work(tmp_path, policies, capsys, policy, preset, message):
    spec_path = write_sweep(tmp_path)
    bare = {k: v for k, v in PRESET.items() if k != "reference_return"}
    spec_path.write_text(
        spec_path.read_text() + "[presets.bare]\n" + "\n".join(f"{k} = {json.dumps(v)}" for k, v in bare.items())
    )
    out = tmp_path / "out"
    argv = ["evaluate", str(spec_path), "--policy", policy.format(policies=policies), "--preset", preset]
    assert tatl([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("tatl evaluate: ") and message in err, err
    assert not out.exists()


def test_context_in_observation_appends_the_condition_context(tmp_path, policies):
    import importlib

    module = importlib.import_module(policies)
    spec = spec_mod.load_spec(write_sweep(tmp_path))
    condition = spec_mod.conditions(spec)[2]  # gain 2
    scoring.score_unit(condition, spec.preset("tiny"), module.watch, 100, context_in_observation=True)
    states = np.concatenate(module.seen)
    assert states.shape[1] == 2 + 4  # theta, theta_dot; mass, length, gravity, gain
    values = suite.check_context("pendulum", "swingup_flipped", {}, {"gain": 2.0})
    np.testing.assert_array_equal(states[:, 2:], np.broadcast_to(list(values.values()), (len(states), 4)))
    assert values["gain"] == 2.0


@pytest.fixture(scope="module")
def sweep_run(tmp_path_factory):
    """A tiny run of the gain sweep: rl on seed 100, every condition."""
    from tatl_mj.experiments.run import runner

    folder = tmp_path_factory.mktemp("sweep-run")
    spec = spec_mod.load_spec(write_sweep(folder))
    summary = runner.run([spec], "tiny", [100], folder / "run", workers=1, methods=["rl"], progress=False)
    return spec, folder / "run", summary


def test_a_builtin_methods_policy_reproduces_its_records_final_return(sweep_run):
    from tatl_mj.experiments.run import method_unit, source_unit

    spec, _, summary = sweep_run
    condition = spec_mod.conditions(spec)[2]
    preset = spec.preset("tiny")
    with determinism.one_thread():  # as its unit learned it
        artifacts = source_unit.learn_source(condition, preset, 100)
        transfer = spec_mod.methods_from_spec(condition, preset, ["rl"])["rl"]
        policy = method_unit.learned_policy(condition, preset, 100, transfer, artifacts, preset.target_budgets[-1])
    row = scoring.score_unit(condition, preset, policy, 100)
    experiment = summary["experiments"][condition.name]
    assert row["mean_return"] == experiment["methods"]["rl"]["final_return"][0]
    assert row["random_return"] == experiment["random_returns"][0]
    assert row["normalised"] == pytest.approx(experiment["methods"]["rl"]["normalised"][0][-1], rel=1e-12)


def test_plot_draws_one_panel_per_policy_on_a_shared_scale(sweep_run, tmp_path, policies, drawn, capsys):
    spec, run, _ = sweep_run
    out = tmp_path / "zero"
    argv = ["evaluate", spec.path, "--policy", f"{policies}:zero", "--preset", "tiny", "--seeds", "1"]
    assert tatl([*argv, "--out", str(out), "--transitions", "2500", "--name", "zero torque"]) == 0
    figure = tmp_path / "scores.png"
    assert tatl(["plot", str(out), str(run), "--out", str(figure)]) == 0
    assert figure.stat().st_size > 1000
    axes = drawn[-1].axes
    assert [a.get_title() for a in axes] == [
        "RL (no transfer)\n120 target transitions",
        "zero torque\n2.5k target transitions",
    ]
    assert axes[0].get_shared_y_axes().joined(axes[0], axes[1])
    assert [t.get_text() for t in axes[1].get_xticklabels()] == ["gain=0.5", "gain=1", "gain=2"]
    assert tatl(["plot", str(out)]) == 0 and (out / "scores.png").exists()
    assert tatl(["plot", str(out), str(run)]) == 2 and "--out" in capsys.readouterr().err


def test_sb3_actions_reach_the_target_as_the_gym_id_applies_them():
    sb3 = pytest.importorskip("tatl_mj.sb3", exc_type=ImportError)
    import gymnasium
    from stable_baselines3 import SAC

    from tatl_mj import gym as tatl_gym

    env = gymnasium.make("tatl_mj/PendulumSwingupFlipped-v2").unwrapped
    model = SAC("MlpPolicy", env, seed=0, device="cpu")
    policy = sb3.model_policy(model, "pendulum", "swingup_flipped", {}, 2)
    states = np.random.default_rng(0).uniform([-3, -8], [3, 8], size=(16, 2))
    actions, _ = model.predict(states, deterministic=True)
    values = policy(states)
    assert values.shape == (16, 1)
    for action, value in zip(actions, values):  # the id's step applies actuator_values(a, its space, its scale)
        np.testing.assert_array_equal(value, np.clip(action.astype(np.float64), -1, 1) * env.actuator_limit)
    # Beyond the space is clipped, as the id's step clips; a space of another task is refused.
    space = env.action_space
    scale = tatl_gym.action_scale(space, env.actuator_limit)
    beyond = tatl_gym.batch_actuator_values(np.array([[3.0], [-0.5]]), space, scale)
    np.testing.assert_array_equal(beyond[:, 0], np.array([1.0, -0.5]) * env.actuator_limit[0])
    raw = tatl_gym.action_space(env.actuator_limit, False)[0]
    np.testing.assert_array_equal(tatl_gym.action_scale(raw, env.actuator_limit), [1.0])
    with pytest.raises(ValueError, match="neither of this task's"):
        tatl_gym.action_scale(gymnasium.spaces.Box(-5, 5, (1,)), env.actuator_limit)
    with pytest.raises(ValueError, match=r"observes shape \(2,\)"):
        sb3.model_policy(model, "pendulum", "swingup_flipped", {}, 6)


def test_a_saved_sb3_model_is_scored_with_its_hash(tmp_path, capsys):
    sb3 = pytest.importorskip("tatl_mj.sb3", exc_type=ImportError)
    import gymnasium
    from stable_baselines3 import SAC

    spec_path = write_sweep(tmp_path)
    envs = sb3.vec_env("tatl_mj/PendulumSwingupFlipped-v2", 2, context_in_observation=True)
    model = SAC("MlpPolicy", envs, seed=0, device="cpu")
    path = tmp_path / "agent.zip"
    model.save(path)
    argv = ["evaluate", str(spec_path), "--policy", str(path), "--preset", "tiny", "--seeds", "1"]
    assert tatl([*argv, "--out", str(tmp_path / "no-context")]) == 2
    assert "observes shape (6,)" in capsys.readouterr().err and not (tmp_path / "no-context").exists()
    out = tmp_path / "scored"
    assert tatl([*argv, "--context-in-observation", "--out", str(out), "--command", "python train.py"]) == 0
    manifest = json.loads((out / scoring.MANIFEST).read_text())
    assert manifest["policy"] == {"kind": "stable-baselines3", "algorithm": "SAC", "sha256": sb3.file_sha256(path)}
    assert manifest["command"] == "python train.py" and manifest["context_in_observation"] is True
    # The loaded model, given the condition's context, acts as the trained one on the same observations.
    context = np.array(list(suite.check_context("pendulum", "swingup_flipped", {}, {"gain": 0.5}).values()))
    states = np.random.default_rng(1).normal(size=(5, 2))
    observations = np.concatenate([states, np.tile(context, (5, 1))], axis=1)
    expected = np.clip(model.predict(observations, deterministic=True)[0], -1, 1)
    loaded = sb3.model_policy(sb3.load_model(path), "pendulum", "swingup_flipped", {"gain": 0.5}, 6)
    limit = gymnasium.make("tatl_mj/PendulumSwingupFlipped-v2").unwrapped.actuator_limit
    np.testing.assert_array_equal(scoring.with_context(loaded, context)(states), expected * limit)


def test_the_worked_example_runs_headless_at_a_tiny_budget(tmp_path):
    # scripts/sb3_flipped_gain.py: three agents trained a few hundred steps, saved, scored by
    # `tatl evaluate` and drawn by `tatl plot`; MUJOCO_GL unset, no display, warnings as errors.
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY")}
    env["PYTHONPATH"] = str(ROOT)
    out = tmp_path / "example"
    done = subprocess.run(
        [sys.executable, "-W", "error", "scripts/sb3_flipped_gain.py", "--steps", "300", "--envs", "2"]
        + ["--minutes", "2", "--preset", "smoke", "--eval-seeds", "1", "--out", str(out)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert "Traceback" not in done.stderr and "Warning" not in done.stderr, done.stderr[-3000:]
    for name in ("randomised", "context", "nominal"):
        manifest = json.loads((out / name / "evaluation" / scoring.MANIFEST).read_text())
        assert manifest["transitions"] == 300 and manifest["context_in_observation"] == (name == "context")
        assert len(json.loads((out / name / "evaluation" / scoring.SCORES).read_text())["rows"]) == 3
    assert (out / "scores.png").stat().st_size > 1000
