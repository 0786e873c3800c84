"""The batch runner: results shape, resume after a kill, failure isolation, Ray = local."""

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
import tomllib

import numpy as np
import pytest
from conftest import ROOT, TINY, tiny_spec, write_tiny

from tatl_mj.experiments import spec as spec_mod
from tatl_mj.experiments.report import tables
from tatl_mj.experiments.results import records
from tatl_mj.experiments.results.summary_data import Summary
from tatl_mj.experiments.run import costs, runner


def test_local_run_writes_records_and_summary(tmp_path):
    spec = tiny_spec()
    summary = runner.run([spec], "tiny", [0], tmp_path, workers=1, progress=False)
    exp = summary["experiments"]["ip_to_flipped_ip"]
    assert set(exp["methods"]) == set(spec.methods) >= {"ta-tl", "uma-tl", "rl", "apprentice-fqi", "rl-online"}
    for method in exp["methods"].values():
        assert method["curve"]["samples"] == [40, 120]
        assert len(method["final_return"]) == len(method["samples_to_threshold"]) == 1
    assert exp["threshold"] is not None and exp["random_return"] is not None
    on_disk = json.loads((tmp_path / "summary.json").read_text())
    assert (
        on_disk["experiments"]["ip_to_flipped_ip"]["methods"]["rl"]["final_return"]
        == exp["methods"]["rl"]["final_return"]
    )
    assert not list(tmp_path.rglob("*.tmp"))

    # A rerun of the same command does no work and changes no record.
    stamps = {p: p.stat().st_mtime_ns for p in (tmp_path / "records").rglob("*.json")}
    again = runner.run([spec], "tiny", [0], tmp_path, workers=1, progress=False)
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps
    assert (
        again["experiments"]["ip_to_flipped_ip"]["methods"]["rl"]["final_return"]
        == exp["methods"]["rl"]["final_return"]
    )


def test_mixing_presets_in_one_folder_is_refused(tmp_path):
    records.write_json(tmp_path / "run.json", {"preset": "paper", "experiments": []})
    with pytest.raises(runner.RunFolderError, match="preset 'paper'"):
        runner.run([tiny_spec()], "tiny", [0], tmp_path, workers=1, progress=False)


def test_a_failing_experiment_does_not_take_the_others_down(tmp_path):
    # ... and the run does not look successful: it raises once the others finished.
    good, bad = tiny_spec(), tiny_spec(no_such_option=1)
    stale = records.RunDirectory(tmp_path).failure_path(good.name, 0, "rl")
    stale.parent.mkdir(parents=True)
    stale.write_text("an earlier run's traceback")
    with pytest.raises(runner.RunFailed) as caught:
        runner.run([good, bad], "tiny", [0], tmp_path, workers=1, progress=False, methods=["rl"])
    error = caught.value
    summary = error.summary
    assert summary["experiments"]["ip_to_flipped_ip"]["methods"]["rl"]["final_return"]
    assert any("ip_to_flipped_ip_broken" in f for f in summary["failures"])
    assert json.loads((tmp_path / "summary.json").read_text())["failures"] == summary["failures"]
    failure = (tmp_path / "failures" / "ip_to_flipped_ip_broken__seed0__source.txt").read_text()
    assert "no_such_option" in failure
    assert not stale.exists(), "a unit that now finished keeps no traceback"
    assert (error.failed, error.skipped, error.total) == (1, 1, 4)
    assert str(error) == (
        f"2 of 4 work units did not finish (1 failed, 1 skipped as their source unit failed); "
        f"tracebacks in {tmp_path / 'failures'}/; rerun the same command to retry them"
    )


def test_a_user_domain_and_method_by_import_path_run_with_any_number_of_workers(tmp_path):
    # tests/plugin_domain.py is no part of the package: the spec names it "plugin_domain:point_mass",
    # and its method "zero" as "plugin_method:ZeroTorque"; each worker process imports them itself.
    import plugin_domain

    from tatl_mj import suite

    experiment = spec_mod.parse_spec(tomllib.loads(plugin_domain.SPEC), "point_mass.toml")
    assert "plugin_domain:point_mass" not in suite.DOMAINS  # nothing registered in this process
    summaries = {
        workers: runner.run([experiment], "tiny", [0, 1], tmp_path / str(workers), workers=workers, progress=False)
        for workers in (1, 2)
    }
    for workers, summary in summaries.items():
        assert summary["failures"] == [], workers
        assert list(summary["experiments"][experiment.name]["methods"]) == ["ta-tl", "rl", "zero"]
    for name in ("source", "ta-tl", "rl", "zero"):
        for seed in (0, 1):
            one, two = (
                records.read_json(records.RunDirectory(tmp_path / str(w)).record_path(experiment.name, seed, name))
                for w in (1, 2)
            )
            if name == "source":
                assert one["random_return"] == two["random_return"]
            else:
                assert [p["returns"] for p in one["curve"]] == [p["returns"] for p in two["curve"]], name


def test_killed_run_resumes_without_losing_finished_units(tmp_path):
    spec_path = write_tiny(tmp_path)
    out = tmp_path / "out"
    cmd = [
        sys.executable,
        "-m",
        "tatl_mj.cli",
        "run",
        str(spec_path),
        "--preset",
        "tiny",
        "--seeds",
        "2",
        "--workers",
        "1",
        "--out",
        str(out),
    ]
    env = {**os.environ, "MUJOCO_GL": "egl", "PYOPENGL_PLATFORM": "egl"}
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 240
    while time.time() < deadline and len(list((out / "records").rglob("*.json"))) < 2:
        time.sleep(0.2)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    finished = {p: p.stat().st_mtime_ns for p in (out / "records").rglob("*.json")}
    assert len(finished) >= 2, "the run should have finished some units before the kill"
    assert not (out / "summary.json").exists()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    for path, stamp in finished.items():
        assert path.stat().st_mtime_ns == stamp, f"{path} was recomputed"
    summary = json.loads((out / "summary.json").read_text())
    for method in summary["experiments"]["ip_to_flipped_ip"]["methods"].values():
        assert method["seeds"] == [0, 1]


def test_atomic_write_keeps_the_old_file_on_failure(tmp_path, monkeypatch):
    path = tmp_path / "record.json"
    records.write_json(path, {"ok": 1})

    def boom(*args):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError):
        records.write_json(path, {"ok": 2})
    assert json.loads(path.read_text()) == {"ok": 1}
    assert not list(tmp_path.glob("*.tmp"))


def test_ray_executor_matches_local(tmp_path):
    # Ray is the optional extra tatl-mj[ray]; scripts/setup.sh installs it for the tests.
    spec = tiny_spec()
    local = runner.run([spec], "tiny", [0], tmp_path / "local", workers=1, progress=False)
    distributed = runner.run([spec], "tiny", [0], tmp_path / "ray", workers=2, executor="ray", progress=False)
    for name, method in local["experiments"]["ip_to_flipped_ip"]["methods"].items():
        other = distributed["experiments"]["ip_to_flipped_ip"]["methods"][name]
        assert other["curve"]["mean_return"] == method["curve"]["mean_return"]


def test_affine_mapping_equal_to_identity_gives_identical_results():
    from tatl_mj.experiments.run import method_unit, source_unit

    identity = tiny_spec()
    table = tomllib.loads((ROOT / "tasks" / "ip_to_flipped_ip.toml").read_text())
    table["presets"] = {"tiny": TINY}
    table["source_learning"]["iterations"] = 5
    table["mapping"] = {"kind": "affine", "matrix": [[1.0, 0.0], [0.0, 1.0]]}
    affine = spec_mod.parse_spec(table, "affine.toml")
    preset = identity.preset("tiny")
    a = method_unit.run_method(identity, preset, 0, "ta-tl", source_unit.learn_source(identity, preset, 0))
    b = method_unit.run_method(affine, preset, 0, "ta-tl", source_unit.learn_source(affine, preset, 0))
    # The affine map works in the pendulum's mapping coordinates (angle from hanging), which
    # shifts and wraps angles on the way in and out: equal up to rounding.
    np.testing.assert_allclose([p["returns"] for p in a["curve"]], [p["returns"] for p in b["curve"]], rtol=1e-12)

    table["mapping"]["matrix"] = [[1.0, 0.0, 0.0]]
    with pytest.raises(spec_mod.SpecError, match="mapping.matrix' must be 2 rows"):
        spec_mod.parse_spec(table, "wrong.toml")


def test_clip_policy_is_the_evaluated_policy(tmp_path):
    """`tatl render` builds its policy through the evaluation's path: replaying it under the
    evaluation protocol gives the recorded returns at the largest budget, Algorithm 2 included."""
    import pickle

    import numpy as np

    from tatl_mj.experiments.report import clips
    from tatl_mj.experiments.run import determinism, evaluation

    spec = tiny_spec()
    runner.run([spec], "tiny", [0], tmp_path, workers=1, progress=False)
    artifacts = pickle.loads(records.RunDirectory(tmp_path).blob_path(spec.name, 0).read_bytes())
    preset = spec.preset("tiny")
    for name in spec.methods:
        recorded = json.loads(records.RunDirectory(tmp_path).record_path(spec.name, 0, name).read_text())
        policy = clips.clip_policy(spec, "tiny", 0, name, artifacts)
        returns, _ = evaluation.target_returns(
            spec, preset, policy, determinism.derive_seed(0, spec.name, "evaluation")
        )
        assert list(returns) == recorded["curve"][-1]["returns"], name
        states = artifacts.target_stream.states[:50]
        again = clips.clip_policy(spec, "tiny", 0, name, artifacts)
        np.testing.assert_array_equal(policy(states), again(states))


def test_timings_break_a_run_down_by_phase(tmp_path):
    spec = tiny_spec()
    runner.run([spec], "tiny", [0], tmp_path, workers=1, progress=False, methods=["rl"])
    table = costs.timings(tmp_path)["ip_to_flipped_ip"]
    assert {"source_learning", "target_sampling", "mapping", "rl learn", "rl evaluate"} <= set(table)
    assert all(seconds >= 0 for seconds in table.values()) and table["rl learn"] > 0
    assert "ip_to_flipped_ip:" in costs.format_timings({"ip_to_flipped_ip": table})


def test_each_experiment_runs_and_reports_its_own_methods(tmp_path):
    base = tiny_spec()
    only_rl = dataclasses.replace(base, methods={"rl": base.methods["rl"]})
    only_uma = dataclasses.replace(base, name="other", methods={"uma-tl": base.methods["uma-tl"]})
    summary = runner.run([only_rl, only_uma], "tiny", [0], tmp_path, workers=1, progress=False)
    assert list(summary["experiments"]["ip_to_flipped_ip"]["methods"]) == ["rl"]
    assert list(summary["experiments"]["other"]["methods"]) == ["uma-tl"]
    assert not summary["experiments"]["other"]["seed_sets_differ"]

    assert "Seed sets differ" not in tables.table(
        Summary.from_json(summary)
    )  # neither is faulted for the other's methods


@pytest.mark.parametrize("variant", ["mc_to_ip_triplets", "mc_to_ip_energy"])
def test_learned_and_given_maps_are_recorded_with_their_coefficients(variant):
    from tatl_mj.experiments.run import source_unit

    experiment = spec_mod.load_spec(ROOT / "tasks" / "variants" / f"{variant}.toml")  # resolves its extends
    tiny = spec_mod.Preset(**{**TINY, "target_budgets": tuple(TINY["target_budgets"]), "alignment_samples": 200})
    learner = dataclasses.replace(experiment.source_learning, iterations=5)
    experiment = dataclasses.replace(experiment, presets={"tiny": tiny}, source_learning=learner)
    artifacts = source_unit.learn_source(experiment, experiment.preset("tiny"), 0)
    record = artifacts.mapping_record
    assert np.shape(record["matrix"]) == (2, 2) and len(record["offset"]) == 2
    json.dumps(record)  # it goes into source.json as it is
    if variant == "mc_to_ip_energy":
        # The hanging pendulum (theta = pi, at rest) is the car's valley, x = -pi/6, at rest.
        np.testing.assert_allclose(
            artifacts.mapping.chi_plus(np.array([[np.pi, 0.0]])), [[-np.pi / 6, 0.0]], atol=1e-12
        )
        np.testing.assert_allclose(artifacts.mapping.chi(np.array([[-np.pi / 6, 0.0]])), [[-np.pi, 0.0]], atol=1e-12)


def test_a_variant_runs_under_its_own_name_and_equals_its_built_in(tmp_path):
    # [methods.copy] with method = "ta-tl" and ta-tl's own settings: the same curve, recorded as "copy".
    base = tiny_spec()
    methods = {"ta-tl": base.methods["ta-tl"], "copy": {**base.methods["ta-tl"], "method": "ta-tl"}}
    spec = dataclasses.replace(base, methods=methods)
    summary = runner.run([spec], "tiny", [0], tmp_path, workers=1, progress=False)
    assert list(summary["experiments"][spec.name]["methods"]) == ["ta-tl", "copy"]
    folder = records.RunDirectory(tmp_path)
    curves = [records.read_json(folder.record_path(spec.name, 0, name))["curve"] for name in ("ta-tl", "copy")]
    assert [p["returns"] for p in curves[0]] == [p["returns"] for p in curves[1]]
    with pytest.raises(ValueError, match="unknown method 'copyy' for ip_to_flipped_ip; valid methods: .*'copy'"):
        runner.run([spec], "tiny", [0], tmp_path / "other", workers=1, progress=False, methods=["copyy"])


def test_paper_protocol_data_are_collected_once_and_nest_across_budgets():
    # Each budget's head of one largest collection is exactly a fresh collection of that size.
    from tatl_mj.experiments.run import problems

    spec = spec_mod.load_spec(ROOT / "tasks" / "grid_to_windy.toml")

    def policy(states):
        return (states[:, 0] + 2 * states[:, 1]).astype(np.int64) % 4

    calls = []

    def collect(pol, n):
        calls.append(n)
        return problems._policy_samples(spec, 0, pol, n)

    nested = problems._nested_samples(collect, 300)
    for n in (37, 120, 300):
        got, fresh = nested(policy, n), problems._policy_samples(spec, 0, policy, n)
        for field in dataclasses.fields(fresh):
            np.testing.assert_array_equal(getattr(got, field.name), getattr(fresh, field.name), err_msg=field.name)
    assert calls == [300]
    nested(lambda states: policy(states), 50)  # another policy: collected afresh
    assert calls == [300, 300]


def test_the_premises_are_timed_on_their_own_and_their_share_printed(tmp_path):
    spec = tiny_spec()
    runner.run([spec], "tiny", [0], tmp_path, workers=1, progress=False, methods=["rl", "ta-tl"])
    table = costs.timings(tmp_path)["ip_to_flipped_ip"]
    # TA-TL's unit measured premises (a part of its own); rl measured none, so has no such part.
    assert table["ta-tl premises"] > 0 and "rl premises" not in table
    text = costs.format_timings({"ip_to_flipped_ip": table})
    share = 100 * table["ta-tl premises"] / sum(table.values())
    assert text.splitlines()[-1] == (
        f"the theorem's premises: {table['ta-tl premises']:.1f} s of {sum(table.values()):.1f} s of work ({share:.1f}%)"
    )
