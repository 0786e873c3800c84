"""The methods' roles (tatl_mj.transfer.roles) name registered built-ins, and say what the built-ins do."""

import ast
import inspect

from tatl_mj.transfer import method, registry, roles


def test_every_role_names_a_built_in():
    named = set(roles.SOURCE_FREE) | set(roles.BASELINES) | set(roles.ABLATION_OF)
    named |= {a for ablations in roles.ABLATION_OF.values() for a in ablations}
    assert named <= set(registry.METHODS), sorted(named - set(registry.METHODS))


def test_methods_without_a_source_are_source_free():
    # Not the converse: replan-no-source reads no source Q, yet its class does not withhold it.
    for name in registry.METHODS:
        if not method.contract(registry.build(name)).uses_source:
            assert name in roles.SOURCE_FREE, name
    for name, ablations in roles.ABLATION_OF.items():
        assert set(ablations) <= set(roles.SOURCE_FREE), name


def test_roles_import_no_method():
    tree = ast.parse(inspect.getsource(roles))
    imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    imported |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    assert not {m for m in imported if m and m.startswith("tatl_mj")}, imported


def test_base_of_reads_the_variant_key():
    assert roles.base_of("ta-tl") == "ta-tl"
    assert roles.base_of("mine", {"method": "ta-tl-h", "horizon": 5}) == "ta-tl-h"
    assert roles.plugin_path({"method": "pkg.mod:Cls"}) == "pkg.mod:Cls" and roles.plugin_path({"method": "rl"}) is None
