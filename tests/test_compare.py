"""`tatl compare` against a tiny reference set: refusals before any work, a user's declared
pairs, a built-in run under another name reproducing its reference records, and --check."""

import dataclasses
import json
import shutil

import pytest
from conftest import ROOT, tatl

from tatl_mj.experiments import compare
from tatl_mj.experiments import spec as spec_mod
from tatl_mj.experiments.results import records, reference
from tatl_mj.experiments.run import runner

EXPERIMENT = "tiny_flip"
PLUGINS = {"PYTHONPATH": str(ROOT / "tests")}


def _user_methods():
    import sys

    sys.path.insert(0, str(ROOT / "tests"))
    import plugin_method

    return {"source-policy": plugin_method.SourcePolicy(), "zero": plugin_method.ZeroTorque()}


@pytest.fixture(scope="module")
def compared(tiny_reference, tmp_path_factory):
    """A comparison of a plug-in that uses the source and its declared source-free ablation."""
    path, _, built = tiny_reference
    plan = compare.plan(
        built, [spec_mod.load_spec(path)], _user_methods(), pairs={"ablation": [("source-policy", "zero")]}
    )
    out = tmp_path_factory.mktemp("compared")
    return out, compare.run(plan, out, workers=2, progress=False)


def test_a_plugin_with_its_declared_ablation_is_credited_against_it(compared, tiny_reference):
    out, outcome = compared
    experiment = outcome.summary["experiments"][EXPERIMENT]
    pairs = {(p["method"], p["other"], p["role"]): p for p in experiment["verdicts"]}
    # The user's pair joins the spec's own, judged by the same rule on both questions, and both
    # of the user's methods meet the spec's frozen best baseline.
    assert set(pairs) == {
        ("ta-tl", "apprentice-fqi", "ablation"),
        ("uma-tl", "rl", "ablation"),
        ("source-policy", "zero", "ablation"),
        ("ta-tl", "ta-tl-placebo", "placebo"),
        *(
            (m, "uma-tl", "best baseline")
            for m in ("ta-tl", "ta-tl-placebo", "apprentice-fqi", "source-policy", "zero")
        ),
    }
    for question in ("final", "efficiency"):
        assert pairs["source-policy", "zero", "ablation"][question]["verdict"] in ("credited", "worse", "not credited")
    results = (out / "results.md").read_text()
    assert results.startswith("Your methods (`source-policy`, `zero`) against reference set `tiny` (preset `tiny`")
    assert "Your pairs: `source-policy` against `zero` (ablation)." in results
    assert "| `source-policy` | `zero` (source-free) |" in results
    # Every reference method beside the user's, their records copied from the set.
    assert set(experiment["methods"]) == {
        "ta-tl",
        "ta-tl-placebo",
        "apprentice-fqi",
        "uma-tl",
        "rl",
        "source-policy",
        "zero",
    }
    _, run, _ = tiny_reference
    for seed in (0, 1):
        copied = records.read_json(out / "records" / EXPERIMENT / f"seed{seed}" / "ta-tl.json")
        assert copied == records.read_json(run / "records" / EXPERIMENT / f"seed{seed}" / "ta-tl.json")
    assert outcome.kernels_note is None  # the same machine: the reference's kernels
    assert (out / "figures" / f"{EXPERIMENT}.png").exists()


def test_without_a_declared_ablation_a_plugin_is_only_ranked(compared, tiny_reference, tmp_path):
    out, _ = compared
    path, _, built = tiny_reference
    again = tmp_path / "again"
    shutil.copytree(out, again)  # finished units: nothing is computed again
    plan = compare.plan(built, [spec_mod.load_spec(path)], _user_methods())
    experiment = compare.run(plan, again, workers=1, progress=False).summary["experiments"][EXPERIMENT]
    roles = {(p["method"], p["role"]) for p in experiment["verdicts"]}
    assert ("source-policy", "ablation") not in roles and ("source-policy", "best baseline") in roles
    assert "You declared no ablation or placebo of your own" in (again / "results.md").read_text()


def test_a_built_in_under_another_name_reproduces_its_reference_records(tiny_reference, tmp_path):
    path, run, built = tiny_reference
    done = _cli(str(path), "--reference", str(built.folder), "--methods", "copy=ta-tl", "--out", str(tmp_path))
    assert done.returncode == 0, done.stderr
    summary = records.read_record(tmp_path / "summary.json")
    costs = ("wall_s", "fqi_s", "learn_s", "evaluate_s")
    for seed in (0, 1):
        mine = records.read_json(tmp_path / "records" / EXPERIMENT / f"seed{seed}" / "copy.json")
        theirs = records.read_json(run / "records" / EXPERIMENT / f"seed{seed}" / "ta-tl.json")
        assert set(compare._differences(mine, theirs)) <= _paths(costs)  # bit for bit but its name and costs
        assert [p["returns"] for p in mine["curve"]] == [p["returns"] for p in theirs["curve"]]
        assert mine["method"] == "copy"
    # Run as a variant of ta-tl with the spec's settings, it is paired as ta-tl is, with the same verdicts.
    experiment = summary["experiments"][EXPERIMENT]
    for role, other in (("ablation", "apprentice-fqi"), ("placebo", "ta-tl-placebo"), ("best baseline", "uma-tl")):
        pairs = {
            p["method"]: {k: v for k, v in p.items() if k != "method"}
            for p in experiment["verdicts"]
            if p["role"] == role
        }
        assert pairs["copy"] == pairs["ta-tl"] and pairs["copy"]["other"] == other, role
    lacking = _cli(str(path), "--reference", str(built.folder), "--methods", "copy=ta-tl-h", "--out", str(tmp_path))
    assert lacking.returncode == 2
    assert lacking.stderr == (
        f"tatl compare: --methods copy=ta-tl-h: {path} lists no method 'ta-tl-h' to rename (its methods: "
        "['ta-tl', 'ta-tl-placebo', 'apprentice-fqi', 'uma-tl', 'rl'])\n"
    )


def _paths(keys):
    return {"method"} | {f"curve[{i}].{k}" for i in range(2) for k in keys}


def _cli(*args):
    return tatl("compare", *args, env=PLUGINS)


def test_a_spec_whose_content_differs_is_refused_in_one_line_before_any_work(tiny_reference, tmp_path):
    path, _, built = tiny_reference
    changed = tmp_path / "tiny_flip.toml"
    changed.write_text(path.read_text().replace("zeta = 0.1", "zeta = 0.2", 1))
    mine = spec_mod.content_hash(spec_mod.load_spec(changed), "tiny")
    theirs = built.manifest.experiments[EXPERIMENT]["content_hash"]
    out = tmp_path / "out"
    done = _cli(
        str(changed), "--reference", str(built.folder), "--methods", "plugin_method:ZeroTorque", "--out", str(out)
    )
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr == (
        f"tatl compare: {changed}: the content of 'tiny_flip' differs from the spec reference 'tiny' was made from "
        f"(content hash {mine[:12]} against {theirs[:12]}): compare the spec as tatl-mj 0.1.0 ships it, or make a "
        "reference of your own from a run of yours (`tatl reference build`)\n"
    )
    assert not out.exists()
    # A reformatted copy of the same spec is accepted (its hash is its content's).
    same = tmp_path / "same.toml"
    same.write_text("# reformatted\n" + path.read_text().replace("gamma = 0.95", "gamma = 9.5e-1"))
    compare.check_spec(built, spec_mod.load_spec(same))


def test_other_seeds_another_preset_schema_or_dynamics_are_refused(tiny_reference, tmp_path):
    path, _, built = tiny_reference
    spec = spec_mod.load_spec(path)
    methods = _user_methods()
    with pytest.raises(compare.CompareError) as caught:
        compare.plan(built, [spec], methods, seeds=[0, 1, 2])
    assert str(caught.value) == (
        "seeds 0-2: reference 'tiny' holds seeds 0, 1; leave --seeds and --first-seed out, or pick the reference "
        "of those seeds (`tatl reference list`)"
    )
    with pytest.raises(compare.CompareError, match="^--preset smoke: reference 'tiny' was run with preset 'tiny'; "):
        compare.plan(built, [spec], methods, preset="smoke")
    older = dataclasses.replace(built, manifest=dataclasses.replace(built.manifest, schema_version=1))
    with pytest.raises(compare.CompareError) as caught:
        compare.plan(older, [spec], methods)
    assert str(caught.value) == (
        "reference 'tiny' holds records of schema 1; this tatl-mj writes schema 2: use a reference set made by "
        "this version (`tatl reference list`)"
    )
    moved = json.loads(json.dumps(built.manifest.experiments))
    moved[EXPERIMENT]["dynamics"]["pendulum/swingup_flipped"] = 2
    other = dataclasses.replace(built, manifest=dataclasses.replace(built.manifest, experiments=moved))
    with pytest.raises(compare.CompareError) as caught:
        compare.plan(other, [spec], methods)
    assert str(caught.value) == (
        f"{path}: its tasks' dynamics versions {{'pendulum/swingup': 1, 'pendulum/swingup_flipped': 1}} are not "
        "those of reference 'tiny' ({'pendulum/swingup': 1, 'pendulum/swingup_flipped': 2}): its records do not "
        "hold for these tasks; use a reference made with them"
    )


def test_names_and_pairs_that_cannot_be_compared_are_refused(tiny_reference):
    path, _, built = tiny_reference
    spec = spec_mod.load_spec(path)
    zero = _user_methods()["zero"]
    with pytest.raises(compare.CompareError) as caught:
        compare.plan(built, [spec], {"rl": zero})
    assert str(caught.value) == (
        "--methods: 'rl' names a method of reference 'tiny'; give yours a name of its own (its `name`)"
    )
    with pytest.raises(compare.CompareError) as caught:
        compare.plan(built, [spec], {"zero": zero}, pairs={"placebo": [("zero", "nope")]})
    assert str(caught.value) == (
        "--placebo zero=nope: 'nope' is neither one of --methods (['zero']) nor a method of reference 'tiny' in "
        "tiny_flip"
    )
    # A reference method may be the ablation.
    plan = compare.plan(built, [spec], {"zero": zero}, pairs={"ablation": [("zero", "rl")]})
    assert plan.pairs == {"ablation": (("zero", "rl"),), "placebo": ()}


def test_check_reports_a_reproduced_unit_and_names_what_differs(tiny_reference, tmp_path):
    path, run, built = tiny_reference
    done = _cli(str(path), "--reference", str(built.folder), "--check")
    assert done.returncode == 0, done.stderr
    plan = compare.plan(built, [spec_mod.load_spec(path)], {})
    experiment, seed, method = compare.cheapest_unit(plan)
    kernels = json.loads((run / "records" / experiment / f"seed{seed}" / f"{method}.json").read_text())["kernels"]
    assert done.stdout == (
        f"reproduced bit for bit: {experiment}/seed{seed}/{method} and its source unit, with kernels {kernels!r}\n"
    )
    # A reference whose record differs in one number is not reproduced, and the field is named.
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    record_path = copy / "records" / experiment / f"seed{seed}" / f"{method}.json"
    record = json.loads(record_path.read_text())
    record["curve"][0]["mean_return"] += 1e-9
    record_path.write_text(json.dumps(record))
    altered = reference.build(copy, "altered", "tatl run ...", tmp_path / "sets")
    result = compare.check(compare.plan(altered, [spec_mod.load_spec(path)], {}), (experiment, seed, method))
    assert not result.reproduced and result.differences == (f"{method}.curve[0].mean_return",)
    assert str(result) == (
        f"not reproduced: {experiment}/seed{seed}/{method} differs in 1 fields ({method}.curve[0].mean_return); "
        f"with the reference's own kernels ({kernels!r})"
    )


def test_a_comparison_folder_belongs_to_one_reference(compared, tiny_reference, tmp_path):
    out, _ = compared
    path, run, _ = tiny_reference
    other = reference.build(run, "other", "tatl run ...", tmp_path / "sets")
    plan = compare.plan(other, [spec_mod.load_spec(path)], _user_methods())
    with pytest.raises(compare.CompareError) as caught:
        compare.run(plan, out, progress=False)
    assert (
        str(caught.value) == f"--out {out}: holds a comparison against reference 'tiny', not 'other'; use another --out"
    )


def test_kernels_other_than_the_references_are_said_once_with_the_fragile_verdicts(tiny_reference):
    path, _, built = tiny_reference
    fragile = ({"experiment": EXPERIMENT, "method": "ta-tl", "versus": "uma-tl", "why": "rounding"},)
    manifest = dataclasses.replace(built.manifest, fragile_verdicts=fragile)
    plan = compare.plan(dataclasses.replace(built, manifest=manifest), [spec_mod.load_spec(path)], _user_methods())
    here = next(iter(built.manifest.kernels))
    assert compare.kernels_note(plan, {here: 4}, None) is None
    note = compare.kernels_note(plan, {"openblas 0.3.1 Haswell; numpy baseline": 4}, None)
    assert note == (
        "note: your units were computed with the arithmetic kernels ['openblas 0.3.1 Haswell; numpy baseline'], "
        f"reference 'tiny''s with [{here!r}]: per-seed returns can differ, and these verdicts are known to move "
        "with the kernels: tiny_flip: ta-tl vs uma-tl"
    )


def test_a_run_folder_holds_records_that_name_their_kernels_and_dynamics(tiny_reference):
    _, run, _ = tiny_reference
    record = records.read_json(run / "records" / EXPERIMENT / "seed0" / "ta-tl.json")
    assert record["dynamics"] == {"pendulum/swingup": 1, "pendulum/swingup_flipped": 1}
    assert record["schema_version"] == records.SCHEMA_VERSION
    assert all(p["target_transitions"] - p["rollout_transitions"] == p["samples_used"] for p in record["curve"])
    assert runner  # the runner wrote them (imported for its side of the contract)


def test_the_compare_command_resumes_a_comparison_and_names_what_it_wrote(compared, tiny_reference, tmp_path):
    out, _ = compared
    path, _, built = tiny_reference
    again = tmp_path / "again"
    shutil.copytree(out, again)
    methods = "plugin_method:SourcePolicy,plugin_method:ZeroTorque"
    done = _cli(
        str(path), "--reference", str(built.folder), "--methods", methods, "--ablation", "source-policy=zero",
        "--out", str(again),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[-1] == f"wrote {again / 'results.md'}"
    assert (again / "results.md").read_text() == (out / "results.md").read_text()
    bad = _cli(
        str(path), "--reference", str(built.folder), "--methods", methods, "--ablation", "zero", "--out", str(again)
    )
    assert bad.returncode == 2
    assert bad.stderr == "tatl compare: --ablation zero: expected YOURS=ABLATION, e.g. mine=mine-no-source\n"
