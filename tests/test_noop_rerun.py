"""A finished run's rerun reuses its physics report (physics.json) instead of timing MuJoCo again."""

import json

import pytest
from conftest import tatl, write_tiny

from tatl_mj.experiments.results import records
from tatl_mj.experiments.run import costs


def _record(run: records.RunDirectory, seed: int, substeps: int) -> None:
    records.write_json(
        run.record_path("exp", seed, "rl"),
        {"wall_s": 2.0, "fqi_s": 1.0, "physics_substeps": {"pendulum/swingup": substeps}},
    )


def test_the_report_of_unchanged_records_is_reused_and_of_changed_ones_timed_again(tmp_path, monkeypatch):
    run = records.RunDirectory(tmp_path)
    run.record_path("exp", 0, "rl").parent.mkdir(parents=True)
    _record(run, 0, 1000)
    timed = []
    monkeypatch.setattr(
        "tatl_mj.sampling.time_rollout",
        lambda domain, task, seconds, threads: timed.append(task) or {"steps_per_s": 500.0, "substeps": 2},
    )
    first = costs.physics_report(tmp_path, repeats=1)
    assert timed == ["swingup"] and first["physics_s"] == pytest.approx(1.0)
    previous = json.loads(json.dumps(first))  # as physics.json keeps it
    assert costs.physics_report(tmp_path, repeats=1, previous=previous) is previous
    assert timed == ["swingup"]  # nothing timed again
    run.record_path("exp", 1, "rl").parent.mkdir(parents=True)
    _record(run, 1, 3000)  # a unit ran since: its substeps are priced now
    again = costs.physics_report(tmp_path, repeats=1, previous=previous)
    assert timed == ["swingup", "swingup"] and again["physics_s"] == pytest.approx(4.0)


def test_a_rerun_that_runs_no_unit_keeps_physics_json(tmp_path):
    spec = write_tiny(tmp_path)
    out = tmp_path / "out"
    args = (
        "run",
        str(spec),
        "--preset",
        "tiny",
        "--seeds",
        "1",
        "--methods",
        "rl",
        "--workers",
        "1",
        "--out",
        str(out),
    )
    assert tatl(*args).returncode == 0
    physics = (out / "physics.json").read_bytes()
    stamp = (out / "physics.json").stat().st_mtime_ns
    again = tatl(*args)
    assert again.returncode == 0, again.stderr
    assert (out / "physics.json").read_bytes() == physics and (out / "physics.json").stat().st_mtime_ns == stamp


def test_a_rerun_that_runs_no_unit_reuses_the_summary_unless_its_inputs_changed(tmp_path, monkeypatch):
    from conftest import tiny_spec

    from tatl_mj.experiments.results import summary
    from tatl_mj.experiments.run import runner

    spec = tiny_spec()
    only = dict(workers=1, methods=["rl", "rl-reset"], progress=False)
    first = runner.run([spec], "tiny", [0], tmp_path, **only)
    built = []
    real_build = summary.build
    monkeypatch.setattr(summary, "build", lambda *a, **k: built.append(1) or real_build(*a, **k))
    again = runner.run([spec], "tiny", [0], tmp_path, **only)
    # Nothing ran: nothing recomputed, the same summary (as written to summary.json).
    assert built == [] and again["experiments"] == json.loads(json.dumps(first["experiments"]))
    # Another method list (one already done) is another summary: built anew.
    fewer = runner.run([spec], "tiny", [0], tmp_path, **{**only, "methods": ["rl"]})
    assert built == [1] and list(fewer["experiments"][spec.name]["methods"]) == ["rl"]
    # So is a summary written under another verdict rule.
    stale = json.loads((tmp_path / "summary.json").read_text()) | {"verdict_rule_version": 1}
    records.write_json(tmp_path / "summary.json", stale)
    runner.run([spec], "tiny", [0], tmp_path, **{**only, "methods": ["rl"]})
    assert built == [1, 1]
