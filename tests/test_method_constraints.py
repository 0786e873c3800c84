"""Every declared constraint of every method, scikit-learn's common-test style.

For every built-in (``registry.METHODS``) and the test plug-in with declared
constraints (``plugin_method:FixedAction``), for every setting: the table
declares it, its default passes, ``"none"`` means None where None is admitted
(and only where the type admits None), and for every constraint a value it
refuses stops the build with one line naming the owner, the field and what is
valid, whether the method is built from a spec table (``registry.resolve``) or
called in Python.
"""

import dataclasses
import typing

import pytest

from tatl_mj.transfer import registry
from tatl_mj.validation import NONE, InvalidSetting, check, describe

PLUGIN = "plugin_method:FixedAction"


def _methods():
    """(name, class, settings, build from a table, build in Python)."""
    for name, factory in registry.METHODS.items():
        yield name, registry.class_of(name), registry.settings_of(name), factory
    import plugin_method

    cls = plugin_method.FixedAction
    settings = tuple(f.name for f in dataclasses.fields(cls) if f.name != "name")
    yield "fixed", cls, settings, cls


METHODS = list(_methods())


def _table(name, settings):
    return {"method": PLUGIN, **settings} if name == "fixed" else settings


def _cases():
    for name, cls, settings, factory in METHODS:
        for field in settings:
            for i, constraint in enumerate(cls.constraints.get(field, [])):
                if constraint is not None:
                    yield pytest.param(name, cls, field, constraint, factory, id=f"{name}-{field}-{i}")


@pytest.mark.parametrize("name, cls, settings, factory", METHODS, ids=[m[0] for m in METHODS])
def test_every_setting_is_declared_and_its_default_passes(name, cls, settings, factory):
    assert set(settings) <= set(cls.constraints), f"{cls.__name__}: undeclared {set(settings) - set(cls.constraints)}"
    assert set(cls.constraints) <= {f.name for f in dataclasses.fields(cls)}
    default = registry.resolve(name, _table(name, {}))
    hints = typing.get_type_hints(cls)
    for field in settings:
        allowed = cls.constraints[field]
        check(cls.__name__, field, getattr(default, field), allowed)  # the default passes
        optional = type(None) in typing.get_args(hints[field])
        assert (None in allowed) == optional, f"{cls.__name__}.{field}: None admitted iff its type admits None"
        if optional:
            assert getattr(registry.resolve(name, _table(name, {field: NONE})), field) is None


@pytest.mark.parametrize("name, cls, field, constraint, factory", list(_cases()))
def test_a_refused_value_stops_the_build_in_one_line(name, cls, field, constraint, factory):
    bad = constraint.invalid()
    assert not constraint.admits(bad)
    allowed = cls.constraints[field]
    expected = f"{cls.__name__}.{field} must be {describe(allowed)}, got "
    with pytest.raises(InvalidSetting) as from_table:
        registry.resolve(name, _table(name, {field: bad}))
    with pytest.raises(InvalidSetting) as in_python:
        factory(**{field: bad})
    for error in (from_table, in_python):
        message = str(error.value)
        assert message.startswith(expected) and "\n" not in message, message
