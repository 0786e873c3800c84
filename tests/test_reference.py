"""Reference sets: the manifest, the round trip from a run folder and back, and bad sets."""

import hashlib
import json
import shutil

import pytest
from conftest import tatl

from tatl_mj.experiments import spec as spec_mod
from tatl_mj.experiments.results import records, reference

EXPERIMENT = "tiny_flip"


def test_the_manifest_names_what_the_records_depend_on(tiny_reference):
    path, run, built = tiny_reference
    manifest = reference.load(built.folder).manifest
    assert manifest == built.manifest
    assert (manifest.name, manifest.preset, manifest.seeds) == ("tiny", "tiny", (0, 1))
    assert manifest.schema_version == records.SCHEMA_VERSION
    assert manifest.command == f"tatl run {path} --preset tiny --out {run}"
    summary = records.read_record(run / "summary.json")
    assert manifest.verdict_rule_version == summary["verdict_rule_version"]
    assert manifest.package_version == summary["versions"]["tatl-mj"] and manifest.versions == summary["versions"]
    spec = spec_mod.load_spec(path)
    assert manifest.experiments == {
        EXPERIMENT: {
            "content_hash": spec_mod.content_hash(spec, "tiny"),
            "dynamics": {"pendulum/swingup": 1, "pendulum/swingup_flipped": 1},
            "methods": list(spec.methods),
        }
    }
    # Two seeds of a source and five methods, all computed with this machine's kernels.
    assert manifest.records == 12 and manifest.kernels == summary["kernels"] and sum(manifest.kernels.values()) == 12
    for name, digest in manifest.files.items():
        assert hashlib.sha256((built.folder / name).read_bytes()).hexdigest() == digest
    assert not list(built.folder.glob("*.pkl"))  # no pickled sources


def test_a_set_unpacks_to_the_run_it_was_built_from(tiny_reference, tmp_path):
    _, run, built = tiny_reference
    out = tmp_path / "unpacked"
    summary = reference.unpack(built, out)
    originals = sorted(p.relative_to(run) for p in run.glob("records/*/seed*/*.json"))
    assert originals == sorted(p.relative_to(out) for p in out.glob("records/*/seed*/*.json"))
    for relative in originals:  # byte for byte: the same JSON, written the same way
        assert (out / relative).read_bytes() == (run / relative).read_bytes(), relative
    original = records.read_record(run / "summary.json")
    for key in ("experiments", "aggregate", "preset", "seeds", "methods", "kernels", "versions", "schema_version"):
        assert summary[key] == original[key], key
    assert summary["reference"] == "tiny"
    assert records.read_json(out / "run.json") == records.read_json(run / "run.json")
    # tatl plot reads it as any run folder.
    done = tatl("plot", str(out))
    assert done.returncode == 0, done.stderr
    assert (out / "results.md").read_text().count(f"(`{EXPERIMENT}`)") == 1


def test_a_set_whose_data_file_changed_is_refused_naming_it(tiny_reference, tmp_path):
    _, _, built = tiny_reference
    copy = tmp_path / "tiny"
    shutil.copytree(built.folder, copy)
    data = copy / reference.RECORDS
    data.write_bytes(data.read_bytes()[:-10])
    with pytest.raises(reference.ReferenceError) as caught:
        list(reference.load(copy).records())
    assert str(caught.value) == (
        f"{data}: its SHA-256 is not the one {copy / reference.MANIFEST} names (a copy cut short?)"
    )


def test_an_unknown_set_lists_the_valid_ones(tiny_reference):
    _, _, built = tiny_reference
    with pytest.raises(reference.ReferenceError) as caught:
        reference.load("nope", built.folder.parent)
    assert str(caught.value) == (
        "no reference set 'nope'; valid sets: ['tiny'], or the path of a folder holding a manifest.json"
    )


def test_a_run_with_unfinished_units_is_not_packed(tiny_reference, tmp_path):
    _, run, _ = tiny_reference
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    summary = json.loads((copy / "summary.json").read_text())
    summary["failures"] = ["tiny_flip/seed0/rl: RuntimeError: boom (see ...)"]
    (copy / "summary.json").write_text(json.dumps(summary))
    with pytest.raises(reference.ReferenceError) as caught:
        reference.build(copy, "broken", "tatl run ...", tmp_path / "sets")
    assert str(caught.value) == (
        f"{copy}: 1 units did not finish (summary.json's failures); rerun its command until none fail"
    )
    assert not (tmp_path / "sets").exists()


def test_records_that_name_no_dynamics_versions_are_not_packed(tiny_reference, tmp_path):
    _, run, _ = tiny_reference
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    path = copy / "records" / EXPERIMENT / "seed1" / "rl.json"
    record = json.loads(path.read_text())
    del record["schema_version"], record["dynamics"]  # as a record from before either was kept
    path.write_text(json.dumps(record))
    with pytest.raises(reference.ReferenceError, match=f"the records of {EXPERIMENT} name 2 sets of dynamics"):
        reference.build(copy, "old", "tatl run ...", tmp_path / "sets")


def test_the_reference_command_builds_lists_and_unpacks(tiny_reference, tmp_path):
    _, run, _ = tiny_reference
    sets = tmp_path / "sets"
    built = tatl("reference", "--root", str(sets), "build", str(run), "--name", "again", "--command", "tatl run x")
    assert built.returncode == 0, built.stderr
    assert built.stdout == f"wrote {sets / 'again'} (12 records)\n"
    listed = tatl("reference", "--root", str(sets), "list")
    assert listed.stdout == "again: preset tiny, seeds [0, 1], 12 records\n"
    missing = tatl("reference", "--root", str(sets), "unpack", "nope", "--out", str(tmp_path / "u"))
    assert missing.returncode == 2
    assert missing.stderr == (
        "tatl reference: no reference set 'nope'; valid sets: ['again'], or the path of a folder holding a "
        "manifest.json\n"
    )


def test_a_set_built_again_keeps_its_hand_written_fragile_verdicts(tiny_reference, tmp_path):
    _, run, _ = tiny_reference
    first = reference.build(run, "kept", "tatl run ...", tmp_path)
    manifest = json.loads((first.folder / reference.MANIFEST).read_text())
    fragile = [{"experiment": EXPERIMENT, "method": "ta-tl", "versus": "uma-tl", "why": "rounding at 40 samples"}]
    (first.folder / reference.MANIFEST).write_text(json.dumps({**manifest, "fragile_verdicts": fragile}))
    again = reference.build(run, "kept", "tatl run ... (again)", tmp_path)
    assert again.manifest.fragile_verdicts == tuple(fragile) and again.manifest.command == "tatl run ... (again)"
