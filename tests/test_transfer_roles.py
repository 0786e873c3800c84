"""Every method declares its own roles (``method.contract``): the runner's record sharing and the
verdicts read the same ones, and every shipped spec declares the pairs it declared when the roles
were name lists (``tatl_mj.transfer.roles`` before issue 67)."""

import ast
import dataclasses
import inspect
import types

import pytest
from conftest import ROOT

from tatl_mj.experiments.results import pairs
from tatl_mj.experiments.run import runner
from tatl_mj.experiments.spec import conditions, load_spec, spec_to_dict
from tatl_mj.transfer import registry, roles
from tatl_mj.transfer.method import Contract, contract

SPECS = sorted([*ROOT.glob("tasks/*.toml"), *ROOT.glob("tasks/variants/*.toml"), *ROOT.glob("tasks/sweeps/*.toml")])

# The built-ins' roles. Privileged: simulator resets (the -reset protocol), the target's reward
# function at states spread over its reset box (apprentice-fqi) or at its apprentice's predicted
# rollouts (ta-tl's Algorithm 2, on by default), the target's true model or its simulator stepped
# from a chosen state (the oracles).
SOURCE_FREE = {
    "rl",
    "rl-reset",
    "rl-online",
    "apprentice-fqi",
    "apprentice-fqi-samples",
    "apprentice-upright",
    "replan-no-source",
}
BASELINES = {"uma-tl", "rl", "rl-reset", "rl-online", "uma-tl-reset"}
PRIVILEGED = {"rl-reset", "uma-tl-reset", "apprentice-fqi", "ta-tl", "ta-tl-oracle", "ta-tl-h-oracle"}
ABLATION_OF = {
    "rl": ("uma-tl", "uma-tl-prior"),
    "rl-reset": ("uma-tl-reset",),
    "apprentice-fqi": ("ta-tl",),
    "apprentice-fqi-samples": ("ta-tl",),
    "apprentice-upright": ("ta-tl-h",),
    "replan-no-source": ("ta-tl", "ta-tl-replan", "ta-tl-replan-protocol"),
}


def test_built_ins_declare_their_roles():
    for name in registry.METHODS:
        held = contract(registry.build(name))
        assert held.uses_source is (name not in SOURCE_FREE), name
        assert held.baseline is (name in BASELINES), name
        assert held.privileged is (name in PRIVILEGED), name
        assert held.ablation_of == ABLATION_OF.get(name, ()), name
        assert set(held.ablation_of) <= set(registry.METHODS), name


def test_a_method_that_declares_nothing_gets_the_plug_in_defaults():
    bare = types.SimpleNamespace(name="mine", learn=lambda problem, samples: None)
    assert contract(bare) == Contract(check=None)
    held = contract(bare)
    assert (held.uses_source, held.ablation_of, held.baseline, held.privileged) == (True, (), False, False)
    # A table that builds nothing here (tatl compare's user methods in its summary) gets them too.
    assert pairs.roles_of({"mine": {"ablation": "rl"}})["mine"] == Contract()


def test_contradicting_roles_are_refused_in_one_line():
    reads_source = types.SimpleNamespace(name="mine", learn=None, ablation_of=("ta-tl",))
    with pytest.raises(ValueError, match=r"declares ablation_of \['ta-tl'\] but uses the source"):
        contract(reads_source)
    with pytest.raises(ValueError, match="ablation_of must be a tuple of method names, got 'ta-tl'"):
        contract(types.SimpleNamespace(name="mine", learn=None, uses_source=False, ablation_of="ta-tl"))


def test_a_plug_in_declares_its_roles_as_a_built_in_does():
    tables = {"ta-tl": {}, "mine": {"method": "plugin_method:UprightNoSource"}, "rl": {}}
    assert pairs.ablation_pairs(tables) == [("ta-tl", "mine")]
    assert pairs.source_free("mine", tables["mine"]) and pairs.baselines(tables) == ["rl"]


def _preset(spec) -> str:
    return "smoke" if "smoke" in spec.presets else next(iter(spec.presets))


def _shared_by_runner(spec, name: str) -> bool:
    """Whether the runner would share ``name``'s record (its role: no source)."""
    preset = _preset(spec)
    base = runner._experiment_key(spec, preset)
    return runner._share_key(spec, preset, runner.Unit(spec.name, 0, name), {}, base) is not None


@pytest.mark.parametrize("path", SPECS, ids=lambda p: p.stem)
def test_the_runner_and_the_verdicts_give_every_spec_table_one_role(path):
    for condition in conditions(load_spec(path)):
        tables = spec_to_dict(condition)["methods"]  # as summary.json keeps them
        for name in condition.methods:
            assert _shared_by_runner(condition, name) is pairs.source_free(name, tables[name]), (path.stem, name)


def test_a_variant_with_the_zero_reference_is_source_free_to_both():
    spec = load_spec(ROOT / "tasks" / "cartpole_to_bicycle.toml")
    zero = {"method": "ta-tl-h", **spec.methods["apprentice-upright"], "reference": "zero"}
    spec = dataclasses.replace(spec, methods={**spec.methods, "ta-tl-h-zero": zero})
    tables = spec_to_dict(spec)["methods"]
    assert _shared_by_runner(spec, "ta-tl-h-zero") and pairs.source_free("ta-tl-h-zero", tables["ta-tl-h-zero"])
    declared = pairs.ablation_pairs(tables)
    # Not judged as a transfer method; ta-tl-h keeps the ablation the spec lists first.
    assert not [p for p in declared if p[0] == "ta-tl-h-zero"]
    assert [p for p in declared if p[0] == "ta-tl-h"] == [("ta-tl-h", "apprentice-upright")]


# What every shipped spec declared before the roles moved onto the methods (the code of
# tatl_mj.transfer.roles' name lists): a transfer method's ablations where the spec lists them.
# Added since, deliberately: apprentice-fqi-samples (ta-tl's non-privileged source-free
# comparator) beside apprentice-fqi, and its -rbf twin in ta-tl-rbf's ablation key.
ABLATION = {
    "ta-tl": ("apprentice-fqi", "apprentice-fqi-samples"),
    "ta-tl-continuous": ("apprentice-fqi", "apprentice-fqi-samples"),
    "ta-tl-no-alg2": ("apprentice-fqi", "apprentice-fqi-samples"),
    "ta-tl-relative": ("apprentice-fqi", "apprentice-fqi-samples"),  # Algorithm 2's two-sided relative gap
    "ta-tl-rbf": ("apprentice-fqi-rbf", "apprentice-fqi-samples-rbf"),  # the spec's own ablation key
    "ta-tl-h": ("apprentice-upright",),
    "ta-tl-h-no-cart": ("apprentice-upright",),
    "uma-tl": ("rl",),
    "uma-tl-prior": ("rl",),
    "uma-tl-reset": ("rl-reset",),
}
GRID_ABLATION = {
    "ta-tl": ("replan-no-source",),
    "ta-tl-replan": ("replan-no-source",),
    "ta-tl-replan-protocol": ("replan-no-source",),
}
# Per spec, the size of each question's family (final, efficiency). apprentice-fqi-samples and
# its -rbf twin added to each (2 per question against the best baseline where it is not the
# parent's) plus four ablation pairs (ta-tl, ta-tl-continuous, ta-tl-no-alg2 against it;
# ta-tl-rbf against the twin); to the pendulum sweeps 2 ablations and 1 best baseline. And
# ta-tl-relative (Algorithm 2's two-sided gap): its two ablations and the best baseline.
FAMILIES = {
    "cartpole_to_bicycle": (33, 33),  # was (24, 24)
    "grid_to_windy": (14, 14),
    "ip_to_flipped_ip": (25, 25),  # was (16, 16)
    "ip_to_timevarying_ip": (25, 25),  # was (16, 16)
    "mc_to_ip": (26, 26),  # was (17, 17)
    "bicycle_noise_speed": (5, 5),
    "ip_to_flipped_ip_gain": (11, 11),  # was (8, 8)
    "ip_to_timevarying_ip_amplitude": (10, 10),  # was (7, 7)
    "cartpole_to_bicycle_affine": (27, 32),  # was (20, 23); on final rl-reset's pairs are the parent's
    "mc_to_ip_energy": (22, 22),  # was (15, 15): the best-baseline pairs are the parent's
    "mc_to_ip_triplets": (22, 26),  # was (15, 17)
}


@pytest.mark.parametrize("path", SPECS, ids=lambda p: p.stem)
def test_every_shipped_spec_declares_the_pairs_it_declared_before(path):
    for condition in conditions(load_spec(path)):
        spec = spec_to_dict(condition)
        methods = spec["methods"]
        expected = {**ABLATION, **GRID_ABLATION} if condition.target.domain == "gridworld" else ABLATION
        ablations = [(m, a) for m, listed in expected.items() for a in listed if m in methods and a in methods]
        assert sorted(pairs.ablation_pairs(methods)) == sorted(ablations)
        placebos = [(m.removesuffix("-placebo"), m) for m in methods if m.endswith("-placebo")]
        assert pairs.placebo_pairs(methods) == placebos
        assert pairs.baselines(methods) == [m for m in methods if m in BASELINES]
        sizes = pairs.family_sizes(spec)
        assert (sizes["final"], sizes["efficiency"]) == FAMILIES[path.stem]


def test_roles_import_no_method():
    tree = ast.parse(inspect.getsource(roles))
    imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    imported |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    assert not {m for m in imported if m and m.startswith("tatl_mj")}, imported


def test_base_of_reads_the_variant_key():
    assert roles.base_of("ta-tl") == "ta-tl"
    assert roles.base_of("mine", {"method": "ta-tl-h", "horizon": 5}) == "ta-tl-h"
    assert roles.plugin_path({"method": "pkg.mod:Cls"}) == "pkg.mod:Cls" and roles.plugin_path({"method": "rl"}) is None


def test_algorithm2_makes_ta_tl_privileged_and_without_it_it_is_not():
    assert contract(registry.resolve("ta-tl", {})).privileged
    assert not contract(registry.resolve("ta-tl-no-alg2", {"method": "ta-tl", "zeta": None})).privileged
    assert contract(registry.resolve("h", {"method": "ta-tl-h", "zeta": 0.1})).privileged
    assert not contract(registry.resolve("h", {"method": "ta-tl-h"})).privileged


def test_the_verdict_tables_label_every_privileged_side():
    from tatl_mj.experiments.report import privileges
    from tatl_mj.experiments.results.summary_data import PairVerdict

    methods = {"ta-tl": {}, "ta-tl-no-alg2": {"method": "ta-tl", "zeta": None}, "apprentice-fqi": {}, "rl": {}}
    marked = privileges.privileged(methods)
    assert set(marked) == {"ta-tl", "apprentice-fqi"}
    pair = PairVerdict("ta-tl-no-alg2", "apprentice-fqi", "ablation", False, None, None, None)
    assert privileges.against(pair, marked) == (
        "`apprentice-fqi` (source-free, privileged: does not credit or discredit transfer)"
    )
    assert privileges.method_cell("ta-tl-no-alg2", marked) == "`ta-tl-no-alg2`"
    assert privileges.method_cell("ta-tl", marked) == "`ta-tl` (privileged)"
