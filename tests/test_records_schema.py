"""Versioned records: the upgrade of real schema-1 records, and the refusal of a newer schema.

The schema-1 fixtures in tests/data/schema1 are records of a smoke run of the
code before records were versioned (the flipped pendulum, seed 0).
"""

import json
import pickle
from pathlib import Path

import pytest

from tatl_mj.experiments.results import records

SCHEMA1 = Path(__file__).parent / "data" / "schema1"


def old(name: str) -> dict:
    return json.loads((SCHEMA1 / f"{name}.json").read_text())


def test_a_schema1_method_record_gains_its_version_and_its_rollouts():
    record = old("ta-tl")
    assert "schema_version" not in record
    new = records.upgrade(record, "ta-tl.json")
    assert new["schema_version"] == records.SCHEMA_VERSION == 3
    assert all(p["premises"] is None for p in new["curve"])  # schema 3: nothing was measured
    # TA-TL learns from the shared stream: what it counted beyond the samples it kept were rollouts.
    counted = [p["target_transitions"] for p in record["curve"]]
    kept = [p["samples_used"] for p in record["curve"]]
    assert counted == [900, 900, 900] and kept == [100, 100, 100]
    assert [p["rollout_transitions"] for p in new["curve"]] == [800, 800, 800]
    # Nothing else moves.
    moved = ("rollout_transitions", "premises")
    assert [{k: v for k, v in p.items() if k not in moved} for p in new["curve"]] == record["curve"]
    assert new["dynamics"] == {}  # schema 1 named no dynamics versions
    assert {k: v for k, v in new.items() if k not in ("schema_version", "curve", "dynamics")} == {
        k: v for k, v in record.items() if k != "curve"
    }
    assert records.upgrade(new, "ta-tl.json") == new  # the current schema reads as it is


def test_a_method_drawing_its_own_data_charges_no_rollouts():
    record = old("rl-reset")
    assert record["data"] == "reset"
    assert [p["rollout_transitions"] for p in records.upgrade(record)["curve"]] == [0, 0, 0]


def test_records_older_than_counting_kernels_and_protocols_are_read_with_the_old_meaning():
    record = old("ta-tl")
    for key in ("data", "kernels"):
        del record[key]
    for point in record["curve"]:
        del point["target_transitions"]
    new = records.upgrade(record)
    # Before transitions were counted a point counted its budget; before protocols, "shared".
    assert [p["target_transitions"] for p in new["curve"]] == [100, 400, 1600]
    assert [p["rollout_transitions"] for p in new["curve"]] == [0, 300, 1500]
    assert new["data"] == "shared" and new["kernels"] == records.UNKNOWN_KERNELS


def test_a_source_record_gains_its_version_and_names_no_dynamics():
    record = old("source")
    assert records.upgrade(record) == {**record, "schema_version": 3, "dynamics": {}}


def test_a_record_that_no_upgrade_can_complete_is_named_with_what_it_lacks():
    record = old("ta-tl")
    del record["curve"][1]["steps"]
    with pytest.raises(records.RecordError) as caught:
        records.upgrade(record, "records/x/seed0/ta-tl.json")
    assert str(caught.value) == (
        "records/x/seed0/ta-tl.json: a schema-1 record without 'steps', which no upgrade can derive"
    )


def test_a_newer_schema_is_refused_in_one_line_naming_the_file():
    with pytest.raises(records.SchemaError) as caught:
        records.upgrade({**old("ta-tl"), "schema_version": 4}, "runs/x/records/e/seed0/ta-tl.json")
    assert str(caught.value) == (
        "runs/x/records/e/seed0/ta-tl.json: record schema 4 is newer than this tatl-mj reads "
        "(schemas 1 to 3); install a newer tatl-mj to read it"
    )
    with pytest.raises(records.RecordError, match="schema_version must be a whole number >= 1, got '2'"):
        records.upgrade({**old("ta-tl"), "schema_version": "2"}, "x.json")


def test_a_schema1_summary_gains_per_seed_random_returns_and_counted_transitions():
    summary = {
        "preset": "smoke",
        "experiments": {
            "e": {
                "random_return": -5.0,
                "methods": {"rl": {"seeds": [3, 1], "curve": {"samples": [10, 20], "mean_return": [[0, 1], [1, 2]]}}},
            }
        },
    }
    new = records.upgrade(summary)
    experiment = new["experiments"]["e"]
    assert new["schema_version"] == 3 and new["kernels"] == {}
    assert experiment["methods"]["rl"]["premises"] is None
    assert experiment["source_seeds"] == [1, 3] and experiment["random_returns"] == [-5.0, -5.0]
    assert experiment["methods"]["rl"]["data"] == "shared"
    assert experiment["methods"]["rl"]["curve"]["target_transitions"] == [[10, 20], [10, 20]]
    assert summary["experiments"]["e"]["methods"]["rl"]["curve"].keys() == {"samples", "mean_return"}  # a copy


def test_a_run_folder_reads_old_records_upgraded_and_refuses_newer_ones(tmp_path):
    folder = records.RunDirectory(tmp_path)
    path = folder.record_path("e", 0, "ta-tl")
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps(old("ta-tl")))
    assert folder.is_done("e", 0, "ta-tl")
    assert records.read_record(path)["curve"][0]["rollout_transitions"] == 800
    path.write_text(json.dumps({**old("ta-tl"), "schema_version": 9}))
    with pytest.raises(records.SchemaError, match=f"^{path}: record schema 9 is newer"):
        folder.is_done("e", 0, "ta-tl")
    assert path.exists()  # refused, not moved aside as corrupt


def test_every_record_written_names_the_current_schema(tmp_path):
    folder = records.RunDirectory(tmp_path)
    folder.write_unit("e", 0, "rl", {"curve": [], "final_return": 0.0})
    assert records.read_json(folder.record_path("e", 0, "rl"))["schema_version"] == records.SCHEMA_VERSION


def test_a_source_cache_pickled_before_a_module_moved_is_read_at_its_new_home():
    # A run folder started before experiments/ was split, or before run/pipeline.py and
    # transfer/alignment.py were split in parts, names its classes by their old modules;
    # resuming it must read them (protocol 0 writes module paths as plain lines).
    import functools
    import importlib

    import numpy as np

    from tatl_mj.experiments.run import problems, source_unit
    from tatl_mj.transfer import mappings
    from tatl_mj.transfer.intertask_mapping import AffineMapping, IdentityMapping
    from tatl_mj.transfer.manifold_alignment import LinearAlignment
    from tatl_mj.transfer.transition_alignment import TransitionAlignment

    for (_, name), new in records.MOVED_NAMES.items():
        assert hasattr(importlib.import_module(new), name), (name, new)
    eye, zero = np.eye(2), np.zeros(2)
    kept = [
        mappings.MAPPINGS[sorted(mappings.MAPPINGS)[0]],
        IdentityMapping(),
        AffineMapping(2 * eye, zero + 1),
        LinearAlignment(zero, eye, zero, eye, eye, -eye, zero),
        TransitionAlignment(n_neighbors=5),
        problems.QueriedMapping(IdentityMapping(), functools.partial(problems._source_region, None, None)),
    ]
    artifacts = source_unit.SourceArtifacts(
        source_q=None, mapping=kept, target_stream=None, random_return=-1.0, mapping_target_samples=0,
        mapping_source_samples=0, source_samples=3, timings={},
    )  # fmt: skip
    split = pickle.dumps(artifacts, protocol=0)
    for (old, name), new in records.MOVED_NAMES.items():  # as written before the parts were split
        split = split.replace(f"c{new}\n{name}\n".encode(), f"c{old}\n{name}\n".encode())
    assert b"ctatl_mj.experiments.run.pipeline\nSourceArtifacts\n" in split
    assert b"ctatl_mj.transfer.alignment\nLinearAlignment\n" in split
    moved = split
    for old, new in records.MOVED_MODULES.items():  # and before experiments/ was split
        moved = moved.replace(f"c{new}\n".encode(), f"c{old}\n".encode())
    assert b"ctatl_mj.experiments.pipeline\nSourceArtifacts\n" in moved
    for blob in (split, moved):
        with pytest.raises(ModuleNotFoundError):
            pickle.loads(blob)
        read = records.load_blob(blob)
        assert type(read) is source_unit.SourceArtifacts and read.source_samples == 3
        assert read.mapping[0] is kept[0]
        assert [type(m) for m in read.mapping] == [type(m) for m in kept]
        np.testing.assert_array_equal(read.mapping[2].chi(eye), kept[2].chi(eye))
        np.testing.assert_array_equal(read.mapping[3].chi_plus(eye), kept[3].chi_plus(eye))
        assert read.mapping[4] == kept[4]
        assert read.mapping[5].region.func is problems._source_region


def test_a_source_cache_answers_alike_with_or_without_its_derived_values():
    # The inverses and lookups of a source's Q and mapping are derived on first use
    # (cached properties). Older run folders pickled them inside the objects; a fresh
    # cache may hold them or not: either round trip answers bit for bit as the original.
    import numpy as np

    from tatl_mj.description import CellMap
    from tatl_mj.transfer.features import RBF
    from tatl_mj.transfer.fqi import LinearQ
    from tatl_mj.transfer.intertask_mapping import AffineMapping
    from tatl_mj.transfer.manifold_alignment import LinearAlignment
    from tatl_mj.transfer.tabular_q import TabularQ

    states = np.random.default_rng(0).uniform(-1, 1, (7, 2))
    cells = np.array([[0, 0], [0, 1], [1, 0], [2, 1]])
    whitener = np.array([[2.0, 0.3], [0.0, 1.5]])

    def build():
        rng = np.random.default_rng(1)
        return [
            LinearQ(RBF.grid([-1, -1], [1, 1], 9, [0.4, 0.7]), rng.standard_normal((3, 10))),
            LinearQ(RBF.grid([-np.pi, -1], [np.pi, 1], 9, 0.5, periodic=[True, False]), rng.standard_normal((3, 10))),
            AffineMapping(np.array([[1.0, 2.0], [0.5, -1.0]]), np.array([0.1, 0.2])),
            LinearAlignment(np.ones(2), whitener, -np.ones(2), whitener.T, np.eye(2), np.diag([1.0, -2.0]), np.ones(2)),
            TabularQ(rng.standard_normal((4, 3)), cells),
            CellMap(cells),
        ]

    def ask(obj):
        if isinstance(obj, LinearQ):
            return obj.values(states)
        if isinstance(obj, TabularQ):
            return obj.values(cells.astype(float))
        if isinstance(obj, CellMap):
            return obj.index(cells[::-1])
        return np.concatenate([obj.chi(states), obj.chi_plus(states)])

    unused = [pickle.loads(pickle.dumps(obj)) for obj in build()]  # pickled before any value was derived
    originals = build()
    answers = [ask(obj) for obj in originals]
    used = [pickle.loads(pickle.dumps(obj)) for obj in originals]  # with them inside, as older caches
    assert "_inverse" in vars(used[0].features) and "_inverse" not in vars(unused[0].features)
    assert "_lookup" in vars(used[-1]) and "_lookup" not in vars(unused[-1])
    for answer, without, within in zip(answers, unused, used):
        np.testing.assert_array_equal(ask(without), answer)
        np.testing.assert_array_equal(ask(within), answer)


def test_the_grid_planners_old_word_for_the_shared_stream_is_read_as_shared():
    # Before one word named the shared random-policy stream the grid planners wrote "stream".
    unit = {"schema_version": 2, "data": "stream", "curve": [], "final_return": 0.0}
    assert records.upgrade(unit)["data"] == "shared"
    assert records.upgrade({**unit, "data": "reset"})["data"] == "reset"
    summary = {
        "schema_version": 2,
        "experiments": {"grid": {"methods": {"r": {"data": "stream"}, "s": {"data": "online"}}}},
    }
    methods = records.upgrade(summary)["experiments"]["grid"]["methods"]
    assert (methods["r"]["data"], methods["s"]["data"]) == ("shared", "online")


def test_the_grid_planner_learns_from_the_shared_stream_under_that_word():
    from tatl_mj.transfer import registry

    assert registry.build("ta-tl-replan").data == "shared"
    assert registry.build("replan-no-source").data == "shared"
    with pytest.raises(ValueError, match="data"):
        registry.resolve("x", {"method": "ta-tl-replan", "data": "stream"})
