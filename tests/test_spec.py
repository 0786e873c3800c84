"""Experiment specs: the five shipped specs load; malformed ones name file, key and expectation."""

import copy
import dataclasses
import textwrap
import tomllib
from pathlib import Path

import pytest
from conftest import ROOT

from tatl_mj.experiments import spec as spec_mod
from tatl_mj.experiments.results import pairs

TASKS = sorted((Path(__file__).resolve().parents[1] / "tasks").glob("*.toml"))
EXPECTED = {"grid_to_windy", "ip_to_timevarying_ip", "cartpole_to_bicycle", "mc_to_ip", "ip_to_flipped_ip"}


def test_the_five_paper_experiments_ship():
    assert {p.stem for p in TASKS} == EXPECTED


@pytest.mark.parametrize("path", TASKS, ids=lambda p: p.stem)
def test_shipped_spec_loads_with_smoke_and_paper_presets(path):
    spec = spec_mod.load_spec(path)
    assert spec.name == path.stem
    for name in ("smoke", "paper"):
        preset = spec.preset(name)
        assert list(preset.target_budgets) == sorted(preset.target_budgets)
    assert max(spec.preset("paper").target_budgets) > max(spec.preset("smoke").target_budgets)
    # quick.sh's preset: the smoke preset's end budgets on one seed, scored the same way.
    quick, smoke = spec.preset("quick"), spec.preset("smoke")
    assert quick.target_budgets == (smoke.target_budgets[0], smoke.target_budgets[-1]) and quick.seeds == 1
    same = ("source_samples", "alignment_samples", "evaluation_episodes", "evaluation_steps", "reference_return")
    assert all(getattr(quick, f) == getattr(smoke, f) for f in same)


def _base() -> dict:
    return tomllib.loads((TASKS[0].parent / "ip_to_flipped_ip.toml").read_text())


def _error(table: dict) -> str:
    with pytest.raises(spec_mod.SpecError) as info:
        spec_mod.parse_spec(table, "bad.toml")
    return str(info.value)


def test_unknown_key_is_named_with_valid_keys():
    table = _base()
    table["mapping"]["neighbours"] = 3
    message = _error(table)
    assert "bad.toml" in message and "mapping.neighbours" in message and "n_neighbors" in message


def test_wrong_type_is_named():
    table = _base()
    table["source_learning"]["gamma"] = "high"
    message = _error(table)
    assert "source_learning.gamma" in message and "finite number" in message


@pytest.mark.parametrize(
    "edit, needle",
    [
        (lambda t: t["source"].__setitem__("domain", "unicycle"), "valid domains"),
        (lambda t: t["target"].__setitem__("task", "fly"), "valid tasks"),
        (lambda t: t["mapping"].__setitem__("kind", "magic"), "valid choices"),
        (lambda t: t["source_learning"].__setitem__("gamma", 1.5), "source_learning.gamma"),
        (lambda t: t["presets"]["smoke"].__setitem__("target_budgets", [400, 100]), "strictly increasing"),
        (lambda t: t["presets"]["smoke"].__setitem__("evaluation_episodes", 0), "evaluation_episodes"),
        (lambda t: t["presets"]["smoke"].__setitem__("model_samples", 0), "presets.smoke.model_samples"),
        (lambda t: t["presets"]["smoke"].pop("source_samples"), "missing required key"),
        (lambda t: t.pop("presets"), "presets"),
        (lambda t: t["source"]["data"].__setitem__("state_high", [-5.0, -9.0]), "low < high"),
    ],
)
def test_impossible_values_are_named(edit, needle):
    table = copy.deepcopy(_base())
    edit(table)
    assert needle in _error(table)


def test_a_presets_model_samples_reach_the_model_based_learner_unless_its_table_sets_them():
    spec = spec_mod.load_spec(TASKS[0].parent / "ip_to_flipped_ip.toml")
    quick, smoke = spec.preset("quick"), spec.preset("smoke")
    assert quick.model_samples == 5000 and smoke.model_samples is None
    default = spec_mod.methods_from_spec(spec, smoke, ["apprentice-fqi"])["apprentice-fqi"]
    assert default.model_samples == 20000
    assert spec_mod.methods_from_spec(spec, quick, ["apprentice-fqi"])["apprentice-fqi"].model_samples == 5000
    # A method without the setting is untouched; a table's own value wins over the preset's.
    assert not hasattr(spec_mod.methods_from_spec(spec, quick, ["ta-tl"])["ta-tl"], "model_samples")
    own = dataclasses.replace(
        spec, methods={**spec.methods, "apprentice-fqi": {**spec.methods["apprentice-fqi"], "model_samples": 700}}
    )
    assert spec_mod.methods_from_spec(own, quick, ["apprentice-fqi"])["apprentice-fqi"].model_samples == 700


def test_unknown_preset_lists_valid_ones(tmp_path):
    spec = spec_mod.load_spec(TASKS[0])
    with pytest.raises(spec_mod.SpecError, match="valid presets"):
        spec.preset("huge")


def test_invalid_toml_names_the_file(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("name = \n")
    with pytest.raises(spec_mod.SpecError, match="broken.toml.*not valid TOML"):
        spec_mod.load_spec(path)


def test_affine_mapping_keys():
    table = _base()
    table["mapping"] = {"kind": "affine", "matrix": [[1.0, 0.0], [0.0]]}
    assert "mapping.matrix" in _error(table)
    table["mapping"] = {"kind": "identity", "matrix": [[1.0]]}
    assert "only to kind 'affine'" in _error(table)
    table["mapping"] = {"kind": "affine", "matrix": [[1.0, 0.0], [0.0, -1.0]], "offset": [0.5, 0.0]}
    spec = spec_mod.parse_spec(table, "ok.toml")
    assert spec.mapping.matrix == ((1.0, 0.0), (0.0, -1.0))


@pytest.mark.parametrize("path", sorted((TASKS[0].parent / "variants").glob("*.toml")), ids=lambda p: p.stem)
def test_variant_specs_load(path):
    spec = spec_mod.load_spec(path)
    assert spec.name == path.stem and spec.preset("smoke") and spec.preset("paper")


@pytest.mark.parametrize(
    "edit, key, needle",
    [
        # the examples: typos inside feature tables used to load and fail in a worker
        (
            lambda t: t["methods"]["uma-tl"]["features"].__setitem__("centres", 100),
            "methods.uma-tl",
            "unknown keys ['centres']",
        ),
        (
            lambda t: t["methods"]["ta-tl"]["apprentice"].__setitem__("kind", "polynomial"),
            "methods.ta-tl",
            "features kind 'polynomial' is unknown",
        ),
        (
            lambda t: t["source_learning"]["features"].__setitem__("centres", 100),
            "source_learning.features",
            "unknown keys ['centres']",
        ),
        # a setting the choice ignores is refused
        (
            lambda t: t["methods"]["rl"].update(regressor="extra_trees"),
            "methods.rl",
            "RL.features applies to regressor 'linear' only",
        ),
        (
            lambda t: t["source_learning"].update(regressor="extra_trees", ridge=1.0),
            "source_learning.ridge",
            "applies to regressor 'linear' only",
        ),
        (lambda t: t["methods"]["ta-tl"].__setitem__("zeeta", 0.1), "methods.ta-tl", "valid settings"),
        (lambda t: t["methods"].__setitem__("ta-tll", {}), "methods.ta-tll", "valid methods"),
        (
            lambda t: t["methods"]["ta-tl"].__setitem__("zeta", -0.5),
            "methods.ta-tl",
            "TATL.zeta must be a finite number > 0",
        ),
        (lambda t: t.__setitem__("name", "../../escape"), "name", "it names a folder"),
        (lambda t: t["target"].__setitem__("task_kwargs", {"wind": 1}), "target.task_kwargs", "valid"),
        (lambda t: t["source_learning"].__setitem__("method", "q_iteration"), "source_learning.method", "known model"),
        (
            lambda t: (
                t["mapping"].__setitem__("kind", "identity") or t["target"].update(domain="cartpole", task="balance")
            ),
            "mapping.kind",
            "equal state sizes",
        ),
    ],
)
def test_spec_errors_name_the_key_path(edit, key, needle):
    table = copy.deepcopy(_base())
    edit(table)
    message = _error(table)
    assert f"'{key}" in message and needle in message, message


def test_methods_from_spec_builds_what_workers_run():
    spec = spec_mod.load_spec(TASKS[0].parent / "grid_to_windy.toml")
    preset = spec.preset("smoke")
    methods = spec_mod.methods_from_spec(spec, preset)
    assert list(methods) == list(spec.methods)
    # The spec's settings reach the objects (the grid sets Algorithm 2's increment itself) ...
    assert methods["ta-tl"].batch == 5000 and methods["ta-tl"].ridge == 1e-3
    assert methods["rl"].iterations == spec.methods["rl"]["iterations"]
    # ... and where a spec leaves the increment unset, it is the preset's smallest budget.
    pendulum = spec_mod.load_spec(TASKS[0].parent / "ip_to_flipped_ip.toml")
    smoke = pendulum.preset("smoke")
    assert spec_mod.methods_from_spec(pendulum, smoke)["ta-tl"].batch == min(smoke.target_budgets)


# --- a user's own domain and method, by import path ---------------------------------


def _point_mass() -> dict:
    import plugin_domain  # tests/plugin_domain.py: a domain no part of the package

    return tomllib.loads(plugin_domain.SPEC)


def test_a_user_domain_and_method_by_import_path_load():
    spec = spec_mod.parse_spec(_point_mass(), "mine.toml")
    assert spec.source.domain == spec.target.domain == "plugin_domain:point_mass"
    built = spec_mod.methods_from_spec(spec, spec.preset("tiny"))
    assert type(built["zero"]).__name__ == "ZeroTorque" and built["zero"].name == "zero"


@pytest.mark.parametrize(
    "edit, message",
    [
        (
            lambda t: t["source"].__setitem__("domain", "no_such_module:point_mass"),
            "bad.toml: key 'source.domain': domain 'no_such_module:point_mass': cannot import module "
            "'no_such_module' (ModuleNotFoundError: No module named 'no_such_module'); it must be importable "
            "here and in every worker (PYTHONPATH or installed)",
        ),
        (
            lambda t: t["target"].__setitem__("domain", "plugin_domain:pointmass"),
            "bad.toml: key 'target.domain': domain 'plugin_domain:pointmass': module 'plugin_domain' has no "
            "attribute 'pointmass'",
        ),
        (
            lambda t: t["target"].__setitem__("domain", "plugin_domain:NOT_A_DOMAIN"),
            "bad.toml: key 'target.domain': 'plugin_domain:NOT_A_DOMAIN' is not a domain: it needs TASKS, "
            "a non-empty table of task name -> factory, got none",
        ),
        (
            lambda t: t["target"].__setitem__("domain", "point_mass"),
            "bad.toml: key 'target.domain': unknown domain 'point_mass'; valid domains: ['bicycle', 'cartpole', "
            "'gridworld', 'mountain_car', 'pendulum'], or your own as 'module:attribute'",
        ),
        (
            lambda t: t["target"].__setitem__("task", "reach_up"),
            "bad.toml: key 'target.task' is 'reach_up'; valid tasks: ['reach', 'reach_flipped']",
        ),
        (
            lambda t: t["methods"]["zero"].__setitem__("method", "no_such_module:Zero"),
            "bad.toml: key 'methods.zero': method 'no_such_module:Zero': cannot import module 'no_such_module' "
            "(ModuleNotFoundError: No module named 'no_such_module'); it must be importable here and in every "
            "worker (PYTHONPATH or installed)",
        ),
        (
            lambda t: t["methods"]["zero"].__setitem__("method", "plugin_method:Zero"),
            "bad.toml: key 'methods.zero': method 'plugin_method:Zero': module 'plugin_method' has no attribute 'Zero'",
        ),
        (
            lambda t: t["methods"]["zero"].__setitem__("method", "plugin_domain:point_mass"),
            "bad.toml: key 'methods.zero': method 'plugin_domain:point_mass' is not a TransferMethod "
            "(needs a name and learn(problem, samples))",
        ),
        (
            lambda t: t["methods"]["zero"].__setitem__("gain", 0.5),
            "bad.toml: key 'methods.zero': method 'plugin_method:ZeroTorque': ZeroTorque(**settings) failed: "
            "ZeroTorque.__init__() got an unexpected keyword argument 'gain'",
        ),
        (
            lambda t: t["methods"].__setitem__("rl", {"method": "plugin_method:ZeroTorque"}),
            "bad.toml: key 'methods.rl': method 'rl' is a built-in; your own method 'plugin_method:ZeroTorque' "
            "needs a table name of its own",
        ),
        (
            lambda t: t["methods"]["zero"].__setitem__("method", "plugin_method:ClaimsAblation"),
            "bad.toml: key 'methods.zero': method 'zero' declares ablation_of ['ta-tl'] but uses the source: "
            "a source-free ablation declares uses_source = False",
        ),
    ],
    ids=[
        "domain-module",
        "domain-attribute",
        "not-a-domain",
        "unknown-domain",
        "user-task",
        "method-module",
        "method-attribute",
        "not-a-method",
        "method-setting",
        "method-built-in-name",
        "method-roles",
    ],
)
def test_a_bad_import_path_is_one_line_naming_the_key(edit, message):
    table = _point_mass()
    edit(table)
    assert _error(table) == message


def test_the_spec_loader_takes_its_mapping_kinds_from_the_mappings_table():
    from tatl_mj.transfer.mappings import MAPPINGS

    assert tuple(MAPPINGS) == ("identity", "manifold_alignment", "transition_alignment", "affine")


def _write(path, text):
    path.write_text(textwrap.dedent(text))
    return path


def test_a_spec_extends_its_parent_with_only_what_differs(tmp_path):
    parent = _write(tmp_path / "parent.toml", (ROOT / "tasks" / "mc_to_ip.toml").read_text())
    (tmp_path / "variants").mkdir()
    child = _write(
        tmp_path / "variants" / "child.toml",
        """
        extends = "../parent.toml"
        unset = ["paper", "mapping.mu", "mapping.n_neighbors", "methods.uma-tl-prior"]
        name = "child"
        streams = "mc_to_ip"
        [mapping]
        kind = "transition_alignment"
        [methods.ta-tl]
        batch = 5000
        """,
    )
    base, variant = spec_mod.load_spec(parent), spec_mod.load_spec(child)
    assert variant.name == "child" and variant.title == base.title and variant.presets == base.presets
    assert variant.mapping.kind == "transition_alignment" and variant.paper == {}
    # A table merges key by key: ta-tl keeps its apprentice and zeta and gains a batch.
    assert variant.methods["ta-tl"] == {**base.methods["ta-tl"], "batch": 5000}
    assert "uma-tl-prior" in base.methods and "uma-tl-prior" not in variant.methods
    assert set(variant.methods) == set(base.methods) - {"uma-tl-prior"}


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('extends = "missing.toml"\n', "missing.toml: no such spec file"),
        ('extends = "self.toml"\n', "extends itself (a cycle of specs)"),
        ('unset = ["paper"]\n', "key 'unset' needs 'extends'"),
        ('extends = "../tasks/mc_to_ip.toml"\nunset = ["mapping.nope"]\n', "names 'mapping.nope', which"),
        ("extends = 3\n", "key 'extends' must be the path of a parent spec"),
    ],
)
def test_extends_and_unset_fail_in_one_line(tmp_path, text, message):
    (tmp_path / "tasks").mkdir()
    (tmp_path / "tasks" / "mc_to_ip.toml").write_text((ROOT / "tasks" / "mc_to_ip.toml").read_text())
    (tmp_path / "sub").mkdir()
    path = tmp_path / "sub" / "self.toml"
    path.write_text(text)
    with pytest.raises(spec_mod.SpecError) as caught:
        spec_mod.load_spec(path)
    assert message in str(caught.value) and "\n" not in str(caught.value)


@pytest.mark.parametrize("variant", ["cartpole_to_bicycle_affine", "mc_to_ip_energy", "mc_to_ip_triplets"])
def test_the_shipped_variants_differ_from_their_parents_by_what_they_say(variant):
    child = spec_mod.load_spec(ROOT / "tasks" / "variants" / f"{variant}.toml")
    parent = spec_mod.load_spec(ROOT / "tasks" / f"{child.streams}.toml")
    assert child.streams == parent.name and child.paper == {} and parent.paper
    assert (child.source, child.target, child.source_learning, child.presets) == (
        parent.source,
        parent.target,
        parent.source_learning,
        parent.presets,
    )
    assert child.mapping != parent.mapping


def test_an_ablation_key_names_one_method_or_a_list_of_them():
    table = _base()
    table["methods"]["ta-tl-rbf"]["ablation"] = ["apprentice-fqi-rbf", "apprentice-fqi"]
    spec = spec_mod.parse_spec(table, "ok.toml")
    assert ("ta-tl-rbf", "apprentice-fqi") in pairs.ablation_pairs(spec.methods)
    assert ("ta-tl-rbf", "apprentice-fqi-rbf") in pairs.ablation_pairs(spec.methods)
    names = sorted(table["methods"])
    expected = "the name of another method of this spec, or a list of such names without repeats,"
    for bad in ([], ["apprentice-fqi-rbf", "apprentice-fqi-rbf"], ["apprentice-fqi-rbf", "nope"], ["ta-tl-rbf"], 3):
        table["methods"]["ta-tl-rbf"]["ablation"] = bad
        assert _error(table) == f"bad.toml: key 'methods.ta-tl-rbf.ablation' must be {expected} {names}, got {bad!r}"
    table["methods"]["ta-tl-rbf"]["ablation"] = "apprentice-fqi-rbf"
    table["methods"]["ta-tl"]["placebo"] = ["ta-tl-placebo"]  # a placebo is one name
    assert _error(table) == (
        f"bad.toml: key 'methods.ta-tl.placebo' must be the name of another method of this spec {names}, "
        "got ['ta-tl-placebo']"
    )
