"""A finished run's rerun reuses its physics report (physics.json) instead of timing MuJoCo again."""

import json

import pytest
from conftest import tatl, write_tiny

from tatl_mj.experiments import records, runner


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
        "tatl_mj.bench.time_rollout",
        lambda domain, task, seconds, threads: timed.append(task) or {"steps_per_s": 500.0, "substeps": 2},
    )
    first = runner.physics_report(tmp_path, repeats=1)
    assert timed == ["swingup"] and first["physics_s"] == pytest.approx(1.0)
    previous = json.loads(json.dumps(first))  # as physics.json keeps it
    assert runner.physics_report(tmp_path, repeats=1, previous=previous) is previous
    assert timed == ["swingup"]  # nothing timed again
    run.record_path("exp", 1, "rl").parent.mkdir(parents=True)
    _record(run, 1, 3000)  # a unit ran since: its substeps are priced now
    again = runner.physics_report(tmp_path, repeats=1, previous=previous)
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
