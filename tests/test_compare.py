"""`tatl compare` against a tiny reference set: refusals before any work, a user's declared
pairs, a built-in run under another name reproducing its reference records, and --check."""

import dataclasses
import hashlib
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
    # What two seeds can resolve, then the user's own verdicts, before the reference's tables.
    assert "On 2 seeds no pair can be credited or found worse, however clear: even 2 of 2 seeds better" in results
    mine = results[results.index("## Your verdicts") : results.index("## Your verdicts") + 3000]
    assert "| tiny_flip | `source-policy` | `zero` (ablation) | " in mine
    assert "| tiny_flip | `source-policy` | `uma-tl` (best baseline) | " in mine
    assert "| tiny_flip | `source-policy` | `ta-tl` (the built-in TA-TL, outside the rule, privileged) | " in mine
    assert "| tiny_flip | `zero` | `ta-tl` (the built-in TA-TL, outside the rule, privileged) | " in mine
    assert results.index("## Your verdicts") < results.index("| `source-policy` | `zero` (source-free) |")
    claimed = records.read_json(out / "compare.json")
    assert claimed["settings"] is None and claimed["kernels"] is None
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
        f"at methods.ta-tl.zeta (yours 0.2, the reference's 0.1) (content hash {mine[:12]} against {theirs[:12]}): "
        "compare the spec as tatl-mj 0.1.0 ships it, or make a reference of your own from a run of yours "
        "(`tatl reference build`)\n"
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
        "reference 'tiny' holds records of schema 1; this tatl-mj writes schema 3: use a reference set made by "
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
    assert compare.kernels_detail(plan, {here: 4}, None) is None
    other = {"openblas 0.3.1 Haswell; numpy baseline": 4}
    # One short line for the terminal and results.md; the long form goes to compare.json.
    assert compare.kernels_note(plan, other, None) == (
        "note: other arithmetic kernels than reference 'tiny''s; per-seed returns can differ (1 verdict marked as "
        "moving with them; compare.json has the details)"
    )
    assert compare.kernels_detail(plan, other, None) == (
        "your units were computed with the arithmetic kernels ['openblas 0.3.1 Haswell; numpy baseline'], "
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
    assert done.stdout.splitlines()[-2] == f"wrote {again / 'results.md'}"
    assert done.stdout.splitlines()[-1].startswith("On 2 seeds no pair can be credited or found worse")
    assert (again / "results.md").read_text() == (out / "results.md").read_text()
    bad = _cli(
        str(path), "--reference", str(built.folder), "--methods", methods, "--ablation", "zero", "--out", str(again)
    )
    assert bad.returncode == 2
    assert bad.stderr == "tatl compare: --ablation zero: expected YOURS=ABLATION, e.g. mine=mine-no-source\n"


def test_the_users_table_answers_each_pair_and_flags_one_near_random():
    from tatl_mj.experiments import compare_report

    def method(finals, efficiency):
        return {"seeds": [0, 1, 2], "normalised": [[0.0, f] for f in finals], "efficiency": {"per_seed": efficiency}}

    experiment = {
        "compared_seeds": [0, 1, 2],
        "methods": {
            "mine": method([0.05, 0.02, 0.08], [0.01, 0.02, 0.03]),
            "mine-no-source": method([0.01, 0.0, 0.03], [0.0, 0.0, 0.01]),
            "ta-tl": method([0.9, 0.8, 0.95], [0.5, 0.6, 0.7]),
        },
        "verdicts": [],
    }
    answer = {"seeds": {"better": 3, "tied": 0, "worse": 0}, "median_difference": {"value": 0.04}}
    experiment["verdicts"] = [
        {"method": "mine", "other": "mine-no-source", "role": "ablation", "final": {**answer, "verdict": "credited"}}
    ]
    rows = compare_report.rows({"experiments": {"e": experiment}}, ["mine"])
    assert [(r["other"], r["near_random"]) for r in rows] == [("mine-no-source", True), ("ta-tl", False)]
    # The TA-TL pair is answered as the rule answers a pair: 3 of 3 seeds worse.
    assert rows[1]["final"]["seeds"] == {"better": 0, "tied": 0, "worse": 3}
    table = "\n".join(compare_report.table({"experiments": {"e": experiment}}, ["mine"]))
    assert (
        "| e | `mine` | `mine-no-source` (ablation) | credited: 3 of 3 seeds better, median difference +0.04 | "
        "not asked | both near random (median final score < 0.1) |"
    ) in table
    assert compare_report.resolution(10) == (
        "On 10 seeds a pair is credited (or found worse) only when at least 9 of the 10 seeds agree: the exact "
        "sign test's 95% interval then lies clear of 0.5."
    )
    assert compare_report.resolution(5).startswith(
        "On 5 seeds no pair can be credited or found worse, however clear: even 5 of 5 seeds better gives the exact "
        "sign test's 95% interval [0.48, 1.00], which holds 0.5 (it takes at least 6 seeds)"
    )


def _settings(tmp_path, text):
    from tatl_mj.experiments import compare_settings

    path = tmp_path / "mine.toml"
    path.write_text(text)
    return compare_settings.read(path)


def test_a_settings_file_gives_a_plugin_settings_per_experiment_checked_before_any_work(tiny_reference, tmp_path):
    _user_methods()  # puts tests/ on the path
    import plugin_method

    path, _, built = tiny_reference
    spec = spec_mod.load_spec(path)
    fixed = plugin_method.FixedAction()
    settings = _settings(tmp_path, "[fixed.tiny_flip]\nindex = 0\n")
    plan = compare.plan(built, [spec], {"fixed": fixed}, settings=settings)
    assert plan.methods["fixed"] == {EXPERIMENT: plugin_method.FixedAction(index=0)}
    assert plan.settings_used == {"fixed": {EXPERIMENT: {"index": 0}}}
    # The spec's content, and so its hash, is untouched: the reference accepted it above.
    refusals = {
        "[fixd.tiny_flip]\nindex = 0\n": "[fixd] names none of your plug-ins (['fixed'])",
        "[fixed.tiny_flop]\nindex = 0\n": "[fixed.tiny_flop] names no experiment of this comparison (its "
        "experiments: ['tiny_flip'])",
        "[fixed.tiny_flip]\nindex = -1\n": "[fixed.tiny_flip]: FixedAction.index must be ",
        "[fixed.tiny_flip]\nindx = 1\n": "[fixed.tiny_flip]: FixedAction(**settings) failed: ",
        "[fixed]\nindex = 1\n": "fixed.index is not in a table of one experiment; write [fixed.EXPERIMENT]",
    }
    for text, expected in refusals.items():
        with pytest.raises(ValueError) as caught:
            compare.plan(built, [spec], {"fixed": fixed}, settings=_settings(tmp_path, text))
        assert str(caught.value).startswith(f"--settings {tmp_path / 'mine.toml'}: {expected}"), str(caught.value)
        assert "\n" not in str(caught.value)


def test_the_settings_file_is_copied_and_hashed_with_the_comparison(tiny_reference, tmp_path):
    path, _, built = tiny_reference
    settings = tmp_path / "mine.toml"
    settings.write_text("[fixed.tiny_flip]\nindex = 0\n")
    out = tmp_path / "out"
    done = _cli(
        str(path), "--reference", str(built.folder), "--methods", "plugin_method:FixedAction",
        "--settings", str(settings), "--out", str(out),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    claimed = records.read_json(out / "compare.json")
    assert claimed["settings"] == {
        "file": "settings.toml",
        "sha256": hashlib.sha256(settings.read_bytes()).hexdigest(),
        "applied": {"fixed": {EXPERIMENT: {"index": 0}}},
    }
    assert (out / "settings.toml").read_bytes() == settings.read_bytes()
    assert "On 2 seeds no pair can be credited" in done.stdout
    # Other settings into the same folder would leave its records behind them: refused.
    settings.write_text("[fixed.tiny_flip]\nindex = 1\n")
    again = _cli(
        str(path), "--reference", str(built.folder), "--methods", "plugin_method:FixedAction",
        "--settings", str(settings), "--out", str(out),
    )  # fmt: skip
    assert again.returncode == 2 and "holds a comparison made with other --settings" in again.stderr


def test_a_policy_of_the_wrong_shape_is_refused_before_any_source_work(tiny_reference, tmp_path):
    path, _, built = tiny_reference
    out = tmp_path / "out"
    done = _cli(str(path), "--reference", str(built.folder), "--methods", "plugin_method:WrongShape", "--out", str(out))
    assert done.returncode == 2, done.stderr
    assert done.stderr == (
        "tatl compare: --methods: method 'wrong-shape': its policy, learned on a tiny problem of tiny_flip and called "
        "on 5 target states, returned shape (5, 3); pendulum/swingup_flipped takes (n, 1) finite action values or "
        "(n,)\n"
    )
    assert not out.exists()
    run = tatl("run", str(path), "--preset", "tiny", "--methods", "plugin_method:WrongShape", "--out", str(out),
               env=PLUGINS)  # fmt: skip
    assert run.returncode == 2 and run.stderr == done.stderr.replace("tatl compare:", "tatl run:")
    assert not out.exists()
