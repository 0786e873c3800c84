"""The one list of built-in transfer methods, and the one resolver of a method's name.

Each name maps to a factory that takes the method's settings as keyword
arguments (an experiment spec's ``[methods.NAME]`` table) and returns the method
object. A plug-in method is any object with ``name`` and ``learn`` (see
``tatl_mj.transfer.method``); it needs no entry here: :func:`resolve` finds it by
import path, ``"module:attribute"``, for the CLI, the spec loader and the runner
alike. Each method declares its own roles in the reports (``method.contract``).
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import typing
from collections.abc import Collection
from typing import Any, Callable

from tatl_mj import plugins
from tatl_mj.transfer.method import TransferMethod
from tatl_mj.transfer.methods.horizon import HorizonTATL
from tatl_mj.transfer.methods.model_based import ApprenticeFQI
from tatl_mj.transfer.methods.projected import ProjectedSource
from tatl_mj.transfer.methods.replan import OneStepOracle, ReplanTATL
from tatl_mj.transfer.methods.sample_model import ApprenticeFQISamples
from tatl_mj.transfer.methods.target_fqi import RL, UMATL, UMATLPrior
from tatl_mj.transfer.methods.tatl import TATL
from tatl_mj.transfer.roles import PAIR_KEYS, VARIANT_KEY, base_of, plugin_path
from tatl_mj.validation import checked_settings

METHODS: dict[str, Callable[..., TransferMethod]] = {
    # The paper's rule (Algorithms 1 and 2) and its two baselines.
    "ta-tl": TATL,
    "uma-tl": UMATL,
    "rl": RL,
    # Fair-comparison baselines and ablations: other data protocols, a source prior
    # that stays in every fit, and TA-TL's own apprentice without the source.
    "rl-reset": functools.partial(RL, data="reset"),
    "rl-online": functools.partial(RL, data="online"),
    "uma-tl-reset": functools.partial(UMATL, data="reset"),
    "uma-tl-prior": UMATLPrior,
    "apprentice-fqi": ApprenticeFQI,
    # The same apprentice without the source or any privilege: only the counted samples.
    "apprentice-fqi-samples": ApprenticeFQISamples,
    # Extensions, each named apart from the paper's rule, and the ablations that credit them.
    "ta-tl-h": HorizonTATL,
    "apprentice-upright": functools.partial(HorizonTATL, reference="zero"),
    "ta-tl-h-oracle": functools.partial(HorizonTATL, model="oracle"),
    "ta-tl-replan": ReplanTATL,
    "replan-no-source": functools.partial(ReplanTATL, source_prior=False),
    "ta-tl-replan-protocol": functools.partial(ReplanTATL, data="source-policy", prior_scope="unvisited"),
    "ta-tl-oracle": OneStepOracle,
    # References.
    "projected-source": ProjectedSource,
}
"""Built-in methods: name -> factory(**settings)."""


def class_of(name: str) -> type:
    """The class a built-in's factory builds."""
    factory = _factory(name)
    return typing.cast(type, factory.func if isinstance(factory, functools.partial) else factory)


def settings_of(name: str) -> tuple[str, ...]:
    """The setting names a built-in method accepts (its constructor's fields, bar those fixed by the name)."""
    factory = _factory(name)
    fixed = set(factory.keywords) if isinstance(factory, functools.partial) else set()
    fields = dataclasses.fields(class_of(name))
    return tuple(f.name for f in fields if f.init and f.name != "name" and f.name not in fixed)


def _factory(name: str) -> Callable[..., TransferMethod]:
    if name not in METHODS:
        raise ValueError(
            f"unknown method {name!r}; valid methods: {sorted(METHODS)} "
            f"(or a variant: a table with {VARIANT_KEY} = one of them)"
        )
    return METHODS[name]


def _plain(value: Any) -> Any:
    """TOML arrays as tuples (settings are frozen), tables left as dicts."""
    if isinstance(value, list):
        return tuple(_plain(v) for v in value)
    return value


def _settings(settings: dict[str, Any] | None) -> dict[str, Any]:
    """A table's settings: its keys other than ``method`` and the pair keys, arrays as tuples."""
    return {k: _plain(v) for k, v in (settings or {}).items() if k not in (VARIANT_KEY, *PAIR_KEYS)}


def build(name: str, settings: dict[str, Any] | None = None) -> TransferMethod:
    """The built-in method ``name`` (or the variant ``name`` of ``settings["method"]``) with
    ``settings``; ValueError naming an unknown or bad setting."""
    base = base_of(name, settings)
    if base != name and name in METHODS:
        raise ValueError(f"method {name!r} is a built-in; a variant of {base!r} needs a name of its own")
    factory = _factory(base)
    given = _settings(settings)
    valid = settings_of(base)
    unknown = sorted(set(given) - set(valid))
    if unknown:
        raise ValueError(
            f"unknown setting {unknown[0]!r} for method {name!r}; valid settings: "
            f"{sorted([*valid, VARIANT_KEY, *PAIR_KEYS])}"
        )
    return factory(**given, name=name)  # the class checks its settings (its constraints)


def resolve(method: Any, settings: dict[str, Any] | None = None, label: str | None = None) -> TransferMethod:
    """The transfer method ``method`` stands for; ValueError (one line) where it stands for none.

    ``method``: a built-in's name; a spec table's name, whose ``settings`` build a
    built-in, a variant of one (``method = "<built-in>"``) or a user's own class
    (``method = "module:attribute"``, called with the other settings and
    ``name=`` the table's name where it takes one); ``"module:attribute"`` itself
    (a class called without settings, or an instance: the CLI's ``--methods``); or
    a method object, returned as it is once it meets the contract (``label``: the
    name it was given under, for the message).
    """
    if not isinstance(method, str):
        return _contracted(method, label if label is not None else repr(method))
    path = method if ":" in method else plugin_path(settings)
    if path is None:
        return build(method, settings)
    if path != method and method in METHODS:
        raise ValueError(f"method {method!r} is a built-in; your own method {path!r} needs a table name of its own")
    obj = plugins.load(path, "method")
    given = _settings(settings)
    if isinstance(obj, type):
        obj = _construct(obj, path, given, None if path == method else method)
    elif given:
        raise ValueError(f"method {path!r} is an instance, not a class: it takes no settings, got {sorted(given)}")
    return _contracted(obj, path)


def _construct(cls: type, path: str, given: dict[str, Any], name: str | None) -> Any:
    """``cls`` called with the settings (checked against its ``constraints`` where it declares
    them) and ``name`` where its constructor takes one."""
    if name is not None:
        if "name" in given:
            raise ValueError(f"method {path!r}: 'name' is the table's name ({name!r}), not a setting")
        try:
            parameters = list(inspect.signature(cls).parameters.values())
        except (TypeError, ValueError):
            parameters = []
        if any(p.name == "name" or p.kind is p.VAR_KEYWORD for p in parameters):
            given = {**given, "name": name}
    given = checked_settings(cls, given)
    try:
        return cls(**given)
    except TypeError as error:
        raise ValueError(f"method {path!r}: {path.partition(':')[2]}(**settings) failed: {error}") from None


def method_forms(listed: Collection[str] = (), renames: bool = False) -> str:
    """The forms ``--methods`` takes, in words, for its one-line refusals."""
    shown = sorted(set(METHODS) | set(listed))
    rename = "NEW=BUILTIN (a method the specs list, under a new name), " if renames else ""
    return (
        f"valid forms: a built-in or a method the specs list ({', '.join(shown)}), {rename}"
        "or your own as module:Class (e.g. mypkg.mine:MyMethod, a colon before the class)"
    )


def parse_methods(text: str, listed: Collection[str] = (), renames: bool = False) -> dict[str, Any]:
    """``--methods`` (``ta-tl,rl,mypkg.mine:MyMethod``) as {name: method object, or None for a
    built-in or a method the specs list (``listed``)}; ValueError, one line naming the entry and
    the valid forms (:func:`method_forms`), for an unknown name, a dotted path without its colon,
    a path that cannot be imported, or an object that is not a method. Checks only; runs nothing.

    A ``module:attribute`` entry is a class (instantiated without arguments) or an instance,
    recorded under its ``name``. ``renames``: ``NEW=BUILTIN`` entries (``tatl compare``) are
    left to the caller.
    """
    methods: dict[str, Any] = {}
    for entry in filter(None, (e.strip() for e in text.split(","))):
        if renames and "=" in entry:
            continue
        if ":" in entry:
            try:
                obj = resolve(entry)
            except ValueError as error:
                raise ValueError(f"{error}; {method_forms(listed, renames)}") from None
            methods[obj.name] = obj
        elif entry in METHODS or entry in listed:
            methods[entry] = None  # the runner checks it against each spec
        elif "." in entry:
            module, _, attribute = entry.rpartition(".")
            raise ValueError(
                f"unknown method {entry!r}: your own is named with a colon before the class "
                f"({module}:{attribute}); {method_forms(listed, renames)}"
            )
        else:
            raise ValueError(f"unknown method {entry!r}; {method_forms(listed, renames)}")
    return methods


def _contracted(obj: Any, label: str) -> TransferMethod:
    if not isinstance(obj, TransferMethod):
        raise ValueError(f"method {label!r} is not a TransferMethod (needs a name and learn(problem, samples))")
    return obj


__all__ = ["METHODS", "build", "class_of", "method_forms", "parse_methods", "resolve", "settings_of"]
