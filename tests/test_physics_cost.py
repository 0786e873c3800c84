"""A run's work is measured against its physics: MuJoCo substeps counted, priced at raw speed."""

import numpy as np
import pytest
from conftest import tiny_spec

from tatl_mj import sampling, suite
from tatl_mj.experiments.results import records
from tatl_mj.experiments.run import costs, runner


def _substeps(key: str) -> int:
    return sampling.physics_substeps().get(key, 0)


def test_evaluation_counts_every_substep_it_takes():
    env = suite.load("pendulum", "swingup", task_kwargs={"random": 0})
    n_sub = int(round(env.control_timestep() / env.physics.timestep()))
    before = _substeps("pendulum/swingup")
    _, lengths = sampling.evaluate("pendulum", "swingup", lambda s: np.zeros((len(s), 1)), 3, 0, max_episode_steps=40)
    assert lengths.tolist() == [40, 40, 40]  # the pendulum never ends early
    assert _substeps("pendulum/swingup") - before == 3 * 40 * n_sub
    # One-step queries: one control step each.
    before = _substeps("pendulum/swingup")
    sampling.step_from("pendulum", "swingup", np.zeros((7, 2)), np.zeros(7, np.int64))
    assert _substeps("pendulum/swingup") - before == 7 * n_sub


def test_physics_report_prices_the_records_substeps_at_raw_speed(tmp_path, monkeypatch):
    run = records.RunDirectory(tmp_path)
    for seed, n in ((0, 1000), (1, 3000)):
        path = run.record_path("exp", seed, "ta-tl")
        path.parent.mkdir(parents=True, exist_ok=True)
        records.write_json(path, {"wall_s": 2.0, "physics_substeps": {"pendulum/swingup": n}})
    older = run.record_path("exp", 0, "rl")
    records.write_json(older, {"wall_s": 50.0})  # no count: left out of both sides
    # Three timings of a drifting machine: the fastest, 1,000 substeps a second, prices the run.
    timings = iter([250.0, 500.0, 400.0])
    monkeypatch.setattr(
        "tatl_mj.sampling.time_rollout",
        lambda domain, task, seconds, threads: {"steps_per_s": next(timings), "substeps": 2},
    )
    report = costs.physics_report(tmp_path)
    assert report["work_s"] == 4.0 and report["physics_s"] == pytest.approx(4.0)
    assert report["ratio"] == pytest.approx(1.0)
    assert report["by_task"]["pendulum/swingup"]["substeps"] == 4000
    assert report["records_without_counts"] == 1
    assert "work / physics = 1.00x (1 older records without counts left out of both)" in costs.format_physics(report)
    # A ratio just above a 3x target reads as above it.
    above = {**report, "work_s": 3977.6, "physics_s": 1308.4, "ratio": 3977.6 / 1308.4, "records_without_counts": 0}
    assert "work / physics = 3.04x" in costs.format_physics(above)


def test_a_unit_records_the_seconds_of_its_fqi_fits(tmp_path):
    spec = tiny_spec()
    result = runner.run([spec], "tiny", [0], tmp_path, workers=1, progress=False, methods=["rl", "projected-source"])
    assert result["failures"] == []
    run = records.RunDirectory(tmp_path)
    source, rl, projected = (
        records.read_json(run.record_path(spec.name, 0, name)) for name in ("source", "rl", "projected-source")
    )
    # The source is learned by FQI and rl fits one per budget; the projected policy fits nothing.
    assert 0.0 < source["fqi_s"] <= source["wall_s"]
    assert 0.0 < rl["fqi_s"] <= sum(point["learn_s"] for point in rl["curve"])
    assert projected["fqi_s"] == 0.0


def test_the_physics_report_adds_the_fits_to_the_physics_where_every_record_times_them(tmp_path, monkeypatch):
    run = records.RunDirectory(tmp_path)
    for name, fits in (("rl", 3.0), ("ta-tl", 0.5)):
        path = run.record_path("exp", 0, name)
        path.parent.mkdir(parents=True, exist_ok=True)
        records.write_json(path, {"wall_s": 5.0, "fqi_s": fits, "physics_substeps": {"pendulum/swingup": 1000}})
    monkeypatch.setattr(
        "tatl_mj.sampling.time_rollout", lambda domain, task, seconds, threads: {"steps_per_s": 500.0, "substeps": 2}
    )
    report = costs.physics_report(tmp_path)
    assert report["fqi_s"] == 3.5 and report["floor_s"] == pytest.approx(5.5)
    assert costs.format_physics(report).splitlines()[1] == (
        "FQI's fits: 3.5 s of the work; physics at raw speed + FQI's fits = 5.5 s; everything else 4.5 s"
    )
    # Timed on a machine that slowed after the run, the physics can cost more than the work left for it.
    slow = {**report, "physics_s": 8.0, "floor_s": 11.5}
    assert (
        costs.format_physics(slow)
        .splitlines()[1]
        .endswith("everything else -1.5 s (below 0: MuJoCo ran slower when timed than during the run)")
    )
    # A record written before fits were timed: no floor, rather than a floor too low.
    records.write_json(run.record_path("exp", 0, "uma-tl"), {"wall_s": 1.0, "physics_substeps": {}})
    report = costs.physics_report(tmp_path)
    assert report["fqi_s"] is None and report["floor_s"] is None
    assert len(costs.format_physics(report).splitlines()) == 1
