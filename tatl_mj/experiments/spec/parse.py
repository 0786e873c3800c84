"""From a parsed TOML table to a checked ExperimentSpec: each key's type checked against the
schema's hints (lists become tuples, integers floats where a float is due), then its values."""

from __future__ import annotations

import dataclasses
import types
import typing
from typing import Any

from tatl_mj.experiments.spec.checks import validate
from tatl_mj.experiments.spec.schema import ExperimentSpec, Preset, SpecError, fail
from tatl_mj.validation import is_integer, is_number


def _convert(value: Any, hint: Any, path: str, key: str) -> Any:
    """Checks ``value`` against a type hint; converts lists to tuples, ints to floats."""
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):  # "X | None": TOML has no None, so a given value is an X
        (inner,) = [arg for arg in typing.get_args(hint) if arg is not type(None)]
        return _convert(value, inner, path, key)
    if dataclasses.is_dataclass(hint):
        return _build(hint, value, path, key)
    if hint is float:
        if not is_number(value):
            fail(path, key, "a finite number", value)
        return float(value)
    if hint is int:
        if not is_integer(value):
            fail(path, key, "an integer", value)
        return value
    if hint is str:
        if not isinstance(value, str):
            fail(path, key, "a string", value)
        return value
    if hint is dict or origin is dict:
        if not isinstance(value, dict):
            fail(path, key, "a table", value)
        return value
    if origin is tuple:
        if not isinstance(value, list):
            fail(path, key, "an array", value)
        item = typing.get_args(hint)[0]
        return tuple(_convert(v, item, path, f"{key}[{i}]") for i, v in enumerate(value))
    raise TypeError(f"unsupported spec type {hint!r}")  # a bug in this module, not in the spec


def _build(cls: type, table: Any, path: str, prefix: str) -> Any:
    if not isinstance(table, dict):
        fail(path, prefix, "a table", table)
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.name != "path"}
    unknown = sorted(set(table) - set(fields))
    if unknown:
        raise SpecError(
            f"{path}: unknown key '{_join(prefix, unknown[0])}'; valid keys{' in [' + prefix + ']' if prefix else ''}: "
            f"{sorted(fields)}"
        )
    values = {}
    for name, field in fields.items():
        key = _join(prefix, name)
        if name not in table:
            required = field.default is dataclasses.MISSING and field.default_factory is dataclasses.MISSING
            if required:
                raise SpecError(f"{path}: missing required key '{key}'")
            continue
        values[name] = _convert(table[name], hints[name], path, key)
    return cls(**values)


def _join(prefix: str, name: str) -> str:
    return f"{prefix}.{name}" if prefix else name


def parse_spec(table: dict, path: str = "<spec>") -> ExperimentSpec:
    """Builds and validates a spec from a parsed TOML table."""
    table = dict(table)
    presets = table.pop("presets", None)
    if not isinstance(presets, dict):
        raise SpecError(f"{path}: a [presets.NAME] table is required (e.g. smoke, paper)")
    skeleton = dataclasses.replace(
        _build(ExperimentSpec, {**table, "presets": {}}, path, ""),
        presets={name: _build(Preset, value, path, f"presets.{name}") for name, value in presets.items()},
        path=path,
    )
    validate(skeleton)
    return skeleton
