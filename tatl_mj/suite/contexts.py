"""Contexts: the settings of a task that may differ from one episode (or one env) to the next.

A context is a ``task_kwargs``-style dict of numbers, e.g. ``{"gain": 0.5}`` for
the flipped pendulum or ``{"cg_noise": 0.1, "speed": 1.5}`` for the bicycle.
Each domain declares the keys each task accepts in ``CONTEXTS`` (task name ->
:class:`ContextSpec`), beside the factory whose arguments they are: the unit,
the valid range and where the key lives:

- ``"model"``: a field of the task's parameter dataclass (``params=``) or a
  factory argument that the MJCF model holds (a mass, a length, an actuator
  gain): a vector env gives each simulation the model the task builds with it;
- ``"task"``: a setting of the task itself (the bicycle's rider noise and
  speed), an attribute of the task of the same name: a vector env keeps it as
  a per-simulation array.

A context is checked once, where it enters (:func:`check`): an unknown key or a
value out of range raises ``ValueError`` in one line naming the key and the
valid keys with their units and ranges. Keys that change the action space (the
actuator limits) are not context keys: a batch has one action space.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
from collections.abc import Callable, Mapping
from typing import Any

from tatl_mj.suite import common

SIDES = ("model", "task")


@dataclasses.dataclass(frozen=True)
class ContextKey:
    """One context key: its unit, its valid range ``[low, high]`` and where it lives (``SIDES``).

    ``in_params``: a field of the factory's ``params`` dataclass, else a
    keyword argument of the factory itself.
    """

    name: str
    unit: str
    low: float
    high: float
    side: str
    doc: str = ""
    in_params: bool = False

    def __post_init__(self) -> None:
        if self.side not in SIDES:
            raise ValueError(f"ContextKey {self.name!r}: side must be one of {SIDES}, got {self.side!r}")
        if not self.low <= self.high:
            raise ValueError(f"ContextKey {self.name!r}: low {self.low} > high {self.high}")

    def describe(self) -> str:
        """``name (unit, low..high)``, as error messages list the valid keys."""
        return f"{self.name} ({self.unit}, {self.low:g}..{self.high:g})"


@dataclasses.dataclass(frozen=True)
class ContextSpec:
    """The context keys of one task; ``check`` raises ValueError for values that are each in
    range but not together (e.g. an amplitude above the mass it swings)."""

    keys: tuple[ContextKey, ...] = ()
    params_type: type | None = None
    check: Callable[[Mapping[str, float]], None] | None = None

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(key.name for key in self.keys)

    def key(self, name: str) -> ContextKey:
        return next(k for k in self.keys if k.name == name)

    def valid(self) -> str:
        """The valid keys, their units and ranges, for messages."""
        return ", ".join(key.describe() for key in self.keys) or "none (this task takes no context)"


def check(spec: ContextSpec, context: Any, where: str) -> dict[str, float]:
    """``context`` checked against ``spec``: a dict of known keys to finite numbers in range.

    Returns it as floats, in ``spec``'s key order. ``where`` names the task (and
    which context) in the one-line ValueError.
    """
    if not isinstance(context, Mapping):
        raise ValueError(f"{where}: a context must be a dict of key -> number, got {context!r}; valid: {spec.valid()}")
    unknown = sorted(str(k) for k in context if k not in spec.names)
    if unknown:
        raise ValueError(f"{where}: unknown context key(s) {unknown}; valid: {spec.valid()}")
    out = {}
    for key in spec.keys:
        if key.name not in context:
            continue
        value = context[key.name]
        if not common.is_real(value) or not math.isfinite(float(value)) or not key.low <= float(value) <= key.high:
            raise ValueError(
                f"{where}: context {key.name} must be a number in [{key.low:g}, {key.high:g}] {key.unit}, "
                f"got {value!r}; valid: {spec.valid()}"
            )
        out[key.name] = float(value)
    return out


def defaults(spec: ContextSpec, factory: Callable[..., Any], task_kwargs: Mapping[str, Any]) -> dict[str, float]:
    """Every key's value where no context sets it: from ``task_kwargs`` (its ``params``
    included), else the factory's default."""
    signature = inspect.signature(factory).parameters
    params = task_kwargs.get("params")
    if params is None and spec.params_type is not None:
        params = spec.params_type()
    out = {}
    for key in spec.keys:
        if key.in_params:
            out[key.name] = float(getattr(params, key.name))
        else:
            out[key.name] = float(task_kwargs.get(key.name, signature[key.name].default))
    return out


def full(spec: ContextSpec, base: Mapping[str, float], context: Mapping[str, float], where: str) -> dict[str, float]:
    """The values of every key under ``context`` (checked), ``base`` filling the rest;
    the spec's joint check applied."""
    values = {**base, **context}
    if spec.check is not None:
        try:
            spec.check(values)
        except ValueError as error:
            raise ValueError(f"{where}: {error}; valid: {spec.valid()}") from None
    return values


def task_kwargs_with(spec: ContextSpec, task_kwargs: Mapping[str, Any], values: Mapping[str, float]) -> dict[str, Any]:
    """``task_kwargs`` with ``values`` written in: params fields into ``params``, the rest as keywords."""
    kwargs = dict(task_kwargs)
    values = {k: float(v) for k, v in values.items()}  # plain floats, as a factory writes them into MJCF text
    fields = {k: v for k, v in values.items() if spec.key(k).in_params}
    for name, value in values.items():
        if name not in fields:
            kwargs[name] = value
    if fields:
        params = kwargs.get("params")
        params = spec.params_type() if params is None else params  # type: ignore[misc]
        kwargs["params"] = dataclasses.replace(params, **fields)
    return kwargs


@dataclasses.dataclass(frozen=True)
class ContextSampler:
    """Domain randomisation: a new context drawn at each env's reset, from the sampler's own
    generator ``np.random.default_rng(seed)``.

    ``ranges`` (key -> (low, high)) draws each key uniformly, in the order given;
    ``draw(generator) -> dict`` draws any other law (it gets the generator; every
    draw is checked as a given context is). The draws are a function of
    ``seed`` and the order of the resets alone, so a run is reproducible.
    """

    ranges: Mapping[str, tuple[float, float]] = dataclasses.field(default_factory=dict)
    seed: int = 0
    draw: Callable[[Any], Mapping[str, Any]] | None = None

    def __post_init__(self) -> None:
        if not common.is_real(self.seed) or isinstance(self.seed, float) or self.seed < 0:
            raise ValueError(f"ContextSampler.seed must be an integer >= 0, got {self.seed!r}")
        if (self.draw is None) == (not self.ranges):
            raise ValueError("ContextSampler takes one of ranges (key -> (low, high)) and draw (generator -> dict)")
        if self.draw is not None and not callable(self.draw):
            raise ValueError(f"ContextSampler.draw must be callable (generator -> dict), got {self.draw!r}")

    def check(self, spec: ContextSpec, where: str) -> None:
        """Raises ValueError unless every range names a key of ``spec`` and lies within its valid range."""
        for name, bounds in self.ranges.items():
            if name not in spec.names:
                raise ValueError(f"{where}: unknown context key(s) [{name!r}] in the sampler; valid: {spec.valid()}")
            key = spec.key(name)
            try:
                low, high = (float(b) for b in bounds)
            except (TypeError, ValueError):
                low, high = math.nan, math.nan
            if not key.low <= low <= high <= key.high:
                raise ValueError(
                    f"{where}: sampler range {name} {bounds!r} must be (low, high) within "
                    f"[{key.low:g}, {key.high:g}] {key.unit}, low <= high; valid: {spec.valid()}"
                )

    def sample(self, generator: Any) -> dict[str, Any]:
        """One context, drawn from ``generator``."""
        if self.draw is not None:
            return dict(self.draw(generator))
        return {name: float(generator.uniform(low, high)) for name, (low, high) in self.ranges.items()}
