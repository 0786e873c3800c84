"""The one list of built-in transfer methods, by the names specs, the CLI and reports use.

Each name maps to a factory that takes the method's settings as keyword
arguments (an experiment spec's ``[methods.NAME]`` table) and returns the method
object. A plug-in method is any object with ``name`` and ``learn`` (see
``tatl_mj.transfer.method``); it needs no entry here.
"""

from __future__ import annotations

import dataclasses
import functools
import typing
from typing import Any, Callable

from tatl_mj.transfer.method import TransferMethod
from tatl_mj.transfer.methods.horizon import HorizonTATL
from tatl_mj.transfer.methods.model_based import ApprenticeFQI
from tatl_mj.transfer.methods.projected import ProjectedSource
from tatl_mj.transfer.methods.replan import OneStepOracle, ReplanTATL
from tatl_mj.transfer.methods.target_fqi import RL, UMATL, UMATLPrior
from tatl_mj.transfer.methods.tatl import TATL

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

SOURCE_FREE = ("rl", "rl-reset", "rl-online", "apprentice-fqi", "apprentice-upright", "replan-no-source")
"""Methods that never look at the source: the ablations a transfer win is measured against."""

ABLATION_OF: dict[str, tuple[str, ...]] = {
    "ta-tl": ("apprentice-fqi", "replan-no-source"),
    "ta-tl-h": ("apprentice-upright",),
    "ta-tl-replan": ("replan-no-source",),
    "ta-tl-replan-protocol": ("replan-no-source",),
    "uma-tl": ("rl",),
    "uma-tl-prior": ("rl",),
    "uma-tl-reset": ("rl-reset",),
}
"""Transfer method -> the built-ins that are the same method without the source, in
order of preference: the first a spec lists is the one a win must beat to be credited
to transfer (``ta-tl``: the model-based learner on its own apprentice; on the grid,
whose targets are cells, the planner on the tabular apprentice)."""

BASELINES = ("uma-tl", "rl", "rl-reset", "rl-online", "uma-tl-reset")
"""The comparison methods (reports compare every other method with them); ``-reset``
ones use privileged simulator resets."""


VARIANT_KEY = "method"
"""A spec's ``[methods.NAME]`` table may name a built-in here (``method = "ta-tl-h"``):
NAME is then a variant of it with these settings, reported under NAME (an ablation
such as ``ta-tl-h-no-cart``). Without it, NAME is the built-in itself."""


PAIR_KEYS = ("ablation", "placebo")
"""Keys of a spec's ``[methods.NAME]`` table that declare which method NAME is judged against
(its source-free ablation, its placebo; ``tatl_mj.experiments.verdicts``): not settings."""


def base_of(name: str, settings: dict[str, Any] | None = None) -> str:
    """The built-in a method table builds: its ``method`` key, else its own name."""
    base = (settings or {}).get(VARIANT_KEY, name)
    if not isinstance(base, str):
        raise ValueError(f"{VARIANT_KEY!r} of method {name!r} must name a built-in method, got {base!r}")
    if base != name and name in METHODS:
        raise ValueError(f"method {name!r} is a built-in; a variant of {base!r} needs a name of its own")
    return base


def settings_of(name: str) -> tuple[str, ...]:
    """The setting names a built-in method accepts (its constructor's fields, bar those fixed by the name)."""
    factory = _factory(name)
    fixed = set(factory.keywords) if isinstance(factory, functools.partial) else set()
    cls = factory.func if isinstance(factory, functools.partial) else factory
    return tuple(f.name for f in dataclasses.fields(cls) if f.init and f.name != "name" and f.name not in fixed)


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


def build(name: str, settings: dict[str, Any] | None = None) -> TransferMethod:
    """The built-in method ``name`` (or the variant ``name`` of ``settings["method"]``) with
    ``settings``; ValueError naming an unknown or bad setting."""
    base = base_of(name, settings)
    factory = _factory(base)
    settings = {k: v for k, v in (settings or {}).items() if k not in (VARIANT_KEY, *PAIR_KEYS)}
    valid = settings_of(base)
    unknown = sorted(set(settings) - set(valid))
    if unknown:
        raise ValueError(
            f"unknown setting {unknown[0]!r} for method {name!r}; valid settings: "
            f"{sorted([*valid, VARIANT_KEY, *PAIR_KEYS])}"
        )
    cls = factory.func if isinstance(factory, functools.partial) else factory
    optional = _optional_fields(cls)
    return factory(**{k: None if v == NONE and k in optional else _plain(v) for k, v in settings.items()}, name=name)


NONE = "none"
"""How a spec (TOML, which has no null) says None for a setting that may be None
(``zeta = "none"``: Algorithm 2 off, the apprentice fitted on every sample)."""


@functools.cache
def _optional_fields(cls: type) -> frozenset[str]:
    """The settings of ``cls`` whose type admits None."""
    hints = typing.get_type_hints(cls)
    return frozenset(
        f.name
        for f in dataclasses.fields(cls)
        if type(None) in typing.get_args(hints.get(f.name)) or hints.get(f.name) is type(None)
    )


__all__ = [
    "ABLATION_OF",
    "BASELINES",
    "METHODS",
    "PAIR_KEYS",
    "SOURCE_FREE",
    "VARIANT_KEY",
    "base_of",
    "build",
    "settings_of",
]
