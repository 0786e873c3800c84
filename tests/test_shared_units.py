"""Experiments that share their random streams: a method without a source runs once for all."""

import dataclasses
import tomllib

import pytest
from conftest import tiny_spec

from tatl_mj.experiments import spec as spec_mod
from tatl_mj.experiments.results import records
from tatl_mj.experiments.run import method_unit, problems, runner, source_unit
from tatl_mj.experiments.spec import MappingSpec
from tatl_mj.transfer import method, registry

# Timings and the marks of a shared copy: everything else of a record is its result.
COSTS = {"wall_s", "fqi_s", "physics_substeps", "shared_from"}


def _result(record: dict) -> dict:
    curve = [{k: v for k, v in p.items() if k not in ("learn_s", "evaluate_s", "premises_s")} for p in record["curve"]]
    return {**{k: v for k, v in record.items() if k not in COSTS}, "curve": curve}


def _pair() -> tuple[spec_mod.ExperimentSpec, spec_mod.ExperimentSpec]:
    """The flipped pendulum and a variant with a hand map that draws the parent's streams."""
    parent = tiny_spec()
    mapping = MappingSpec(kind="affine", matrix=((1.0, 0.0), (0.0, 1.0)))
    variant = dataclasses.replace(parent, name="ip_to_flipped_ip_hand", mapping=mapping, streams=parent.name)
    return parent, variant


def test_source_free_built_ins_declare_it_and_transfer_methods_do_not():
    free = {
        "rl",
        "apprentice-fqi",
        "apprentice-fqi-samples",
        "rl-reset",
        "rl-online",
        "apprentice-upright",
        "replan-no-source",
    }
    using = {"ta-tl", "ta-tl-h", "uma-tl", "uma-tl-prior", "uma-tl-reset", "projected-source", "ta-tl-replan"}
    for name in free | using:
        assert method.contract(registry.build(name)).uses_source is (name not in free), name


def test_a_method_without_a_source_is_handed_none():
    spec = tiny_spec()
    preset = spec.preset("tiny")
    artifacts = source_unit.learn_source(spec, preset, 0)
    problem = problems.transfer_problem(spec, preset, artifacts, 0, uses_source=False)
    for field in ("source_q", "mapping", "source_step"):
        with pytest.raises(method.SourceWithheld, match=f"problem.{field} was read"):
            getattr(problem, field).values if field == "source_q" else getattr(problem, field)(None)
    with pytest.raises(method.SourceWithheld):
        problem.projected_source_policy()(artifacts.target_stream.states[:1])
    record = method_unit.run_method(spec, preset, 0, "rl", artifacts)  # learns without reading them
    assert record["mapping_target_samples"] == 0 and len(record["curve"]) == 2

    class Undeclared:
        """Declares that it uses no source, then reads the source Q."""

        name = "undeclared"
        uses_source = False

        def learn(self, problem, samples):
            return problem.source_q.greedy

    with pytest.raises(method.SourceWithheld, match="problem.source_q was read by a method that declares"):
        method_unit.run_method(spec, preset, 0, "undeclared", artifacts, transfer=Undeclared())


def test_shared_units_run_once_and_equal_the_variant_run_alone(tmp_path):
    parent, variant = _pair()
    both = runner.run(
        [parent, variant], "tiny", [0], tmp_path / "both", workers=1, progress=False, methods=["rl", "ta-tl"]
    )
    alone = runner.run([variant], "tiny", [0], tmp_path / "alone", workers=1, progress=False, methods=["rl", "ta-tl"])
    assert both["failures"] == alone["failures"] == []
    pair, single = records.RunDirectory(tmp_path / "both"), records.RunDirectory(tmp_path / "alone")
    for name in ("rl", "ta-tl"):
        mine = records.read_json(pair.record_path(variant.name, 0, name))
        assert _result(mine) == _result(records.read_json(single.record_path(variant.name, 0, name))), name
    copy = records.read_json(pair.record_path(variant.name, 0, "rl"))
    origin = records.read_json(pair.record_path(parent.name, 0, "rl"))
    assert copy["shared_from"] == "ip_to_flipped_ip/seed0/rl" and "shared_from" not in origin
    assert copy["wall_s"] == copy["fqi_s"] == 0.0 and copy["physics_substeps"] == {} and origin["wall_s"] > 0
    assert all(p["learn_s"] == p["evaluate_s"] == p["premises_s"] == 0.0 for p in copy["curve"])
    assert both["experiments"][variant.name]["methods"]["rl"]["shared_from"] == {"0": "ip_to_flipped_ip/seed0/rl"}
    assert both["experiments"][variant.name]["methods"]["ta-tl"]["shared_from"] == {}
    assert {k: v for k, v in _result(copy).items() if k != "experiment"} == {
        k: v for k, v in _result(origin).items() if k != "experiment"
    }
    # ta-tl reads the mapping: computed in each experiment.
    assert "shared_from" not in records.read_json(pair.record_path(variant.name, 0, "ta-tl"))
    # The variant's source unit took the parent's source Q, target samples and random
    # return, and learned only its map: its record is the one it gets alone, but the work.
    costs = COSTS | {"timings", "blob_sha256"}
    shared, own = (records.read_json(d.record_path(variant.name, 0, "source")) for d in (pair, single))
    assert {k: v for k, v in shared.items() if k not in costs} == {k: v for k, v in own.items() if k not in costs}
    assert shared["timings"]["source_learning_s"] == shared["timings"]["target_sampling_s"] == 0.0
    assert own["timings"]["source_learning_s"] > 0.0
    assert shared["random_return"] == records.read_json(pair.record_path(parent.name, 0, "source"))["random_return"]


def test_a_lost_copy_or_origin_comes_back_without_recomputing(tmp_path, monkeypatch):
    parent, variant = _pair()
    run = lambda: runner.run([parent, variant], "tiny", [0], tmp_path, workers=1, progress=False, methods=["rl"])  # noqa: E731
    run()
    folder = records.RunDirectory(tmp_path)
    copy, origin = folder.record_path(variant.name, 0, "rl"), folder.record_path(parent.name, 0, "rl")
    before = {p: _result(records.read_json(p)) for p in (copy, origin)}
    computed = []
    real = method_unit.run_method
    monkeypatch.setattr(method_unit, "run_method", lambda *a, **k: computed.append(a[3]) or real(*a, **k))
    for lost in (copy, origin):
        lost.unlink()
        run()
        assert computed == [] and {p: _result(records.read_json(p)) for p in before} == before
    assert records.read_json(origin)["shared_from"] == "ip_to_flipped_ip_hand/seed0/rl"


def test_a_failed_unit_skips_the_experiments_that_share_it(tmp_path, monkeypatch):
    parent, variant = _pair()

    def fail(*args, **kwargs):
        raise RuntimeError("boom")

    monkeypatch.setattr(method_unit, "run_method", fail)
    with pytest.raises(runner.RunFailed) as caught:
        runner.run([parent, variant], "tiny", [0], tmp_path, workers=1, progress=False, methods=["rl"])
    assert (caught.value.failed, caught.value.skipped) == (1, 1)
    skipped = "ip_to_flipped_ip_hand/seed0/rl: skipped, the unit it shares"
    assert any(skipped in f for f in caught.value.summary["failures"])
    monkeypatch.undo()
    runner.run([parent, variant], "tiny", [0], tmp_path, workers=1, progress=False, methods=["rl"])  # retried
    assert records.RunDirectory(tmp_path).is_done(variant.name, 0, "rl")


def test_experiments_with_other_streams_or_targets_share_nothing():
    parent, variant = _pair()
    alone = dataclasses.replace(variant, streams="")
    moved = dataclasses.replace(variant, target=dataclasses.replace(variant.target, task_kwargs={"gravity": -9.0}))
    for other in (alone, moved):
        specs = {parent.name: parent, other.name: other}
        units, custom = runner._plan([parent, other], "tiny", [0], ["rl"])
        assert runner._shared(specs, "tiny", units, custom) == [], other


def test_a_spec_names_the_streams_it_draws_and_its_sweeps_keep_them():
    from conftest import ROOT

    energy = spec_mod.load_spec(ROOT / "tasks" / "variants" / "mc_to_ip_energy.toml")
    assert energy.stream_name == "mc_to_ip" and tiny_spec().stream_name == "ip_to_flipped_ip"
    sweep = spec_mod.load_spec(ROOT / "tasks" / "sweeps" / "ip_to_flipped_ip_gain.toml")
    assert {c.stream_name for c in spec_mod.conditions(sweep)} == {sweep.name}
    renamed = dataclasses.replace(sweep, streams="other")
    assert {c.stream_name for c in spec_mod.conditions(renamed)} == {"other"}
    table = tomllib.loads((ROOT / "tasks" / "ip_to_flipped_ip.toml").read_text())
    table["condition"] = {"gain": 1.0}
    with pytest.raises(spec_mod.SpecError, match="key 'condition' is set by a sweep"):
        spec_mod.parse_spec(table, "x.toml")


def test_a_lost_source_unit_takes_the_first_experiments_artefacts_again(tmp_path, monkeypatch):
    parent, variant = _pair()
    run = lambda: runner.run([parent, variant], "tiny", [0], tmp_path, workers=1, progress=False, methods=["ta-tl"])  # noqa: E731
    run()
    folder = records.RunDirectory(tmp_path)
    costs = COSTS | {"timings", "blob_sha256"}
    before = {
        k: v for k, v in records.read_json(folder.record_path(variant.name, 0, "source")).items() if k not in costs
    }
    learned = []
    real = source_unit.learn_source
    monkeypatch.setattr(source_unit, "learn_source", lambda *a: learned.append(a[0].name) or real(*a))
    folder.record_path(variant.name, 0, "source").unlink()
    run()
    after = records.read_json(folder.record_path(variant.name, 0, "source"))
    assert learned == [variant.name] and after["timings"]["source_learning_s"] == 0.0
    assert {k: v for k, v in after.items() if k not in costs} == before


def test_copied_rows_count_once_across_experiments():
    from tatl_mj.experiments.results import summary

    scores = [[0.0, 0.5], [0.0, 0.9], [0.0, 1.0], [0.0, 0.2]]
    own = {"seeds": [0, 1, 2, 3], "normalised": scores}
    copied = {**own, "shared_from": {str(s): f"a/seed{s}/rl" for s in range(4)}}
    both = summary.aggregate({"a": {"methods": {"rl": own}}, "b": {"methods": {"rl": copied}}})
    assert (both["rl"]["experiments"], both["rl"]["runs"]) == (1, 4)
    alone = summary.aggregate({"b": {"methods": {"rl": copied}}})  # its origin is not in this summary
    assert (alone["rl"]["experiments"], alone["rl"]["runs"]) == (1, 4)
    twice = summary.aggregate({"a": {"methods": {"rl": own}}, "b": {"methods": {"rl": own}}})
    assert (twice["rl"]["experiments"], twice["rl"]["runs"]) == (2, 8)
