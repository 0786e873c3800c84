"""Reading a spec file: its TOML, with ``extends`` and ``unset`` resolved, parsed and checked."""

from __future__ import annotations

import tomllib
from pathlib import Path

from tatl_mj.experiments.spec.parse import parse_spec
from tatl_mj.experiments.spec.schema import ExperimentSpec, SpecError, fail

EXTENDS, UNSET = "extends", "unset"
"""A spec's loader keys: ``extends = "PARENT.toml"`` (a path relative to the spec) starts
from the parent's settings, the spec's own tables merged over them key by key; ``unset =
["mapping.mu", "methods.NAME"]`` then removes what the parent set and the spec does not
want. Settings only: ``streams`` (not ``extends``) makes two experiments share their random
draws and the records of their methods without a source."""


def load_spec(path: str | Path) -> ExperimentSpec:
    """Reads and validates one experiment spec (TOML), resolving ``extends`` and ``unset``."""
    path = Path(path)
    return parse_spec(_resolved_table(path, ()), str(path))


def _read_table(path: Path) -> dict:
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise SpecError(f"{path}: no such spec file") from None
    except IsADirectoryError:  # [robustness]
        raise SpecError(f"{path}: is a directory, not a spec file") from None
    except UnicodeDecodeError as error:  # [robustness]
        raise SpecError(f"{path}: not a text (UTF-8) file: {error.reason} at byte {error.start}") from None
    except OSError as error:  # [robustness]
        raise SpecError(f"{path}: cannot read: {error.strerror or error}") from None
    except tomllib.TOMLDecodeError as error:
        raise SpecError(f"{path}: not valid TOML: {error}") from None


def _resolved_table(path: Path, children: tuple[Path, ...]) -> dict:
    """The spec's table with its parents' settings merged in (``EXTENDS``), as if written out flat."""
    table = _read_table(path)
    parent, unset = table.pop(EXTENDS, None), table.pop(UNSET, [])
    if parent is None:
        if unset:
            raise SpecError(f"{path}: key '{UNSET}' needs '{EXTENDS}' (there is no parent to unset keys of)")
        return table
    if not isinstance(parent, str) or not parent:
        fail(str(path), EXTENDS, "the path of a parent spec, relative to this one", parent)
    if not isinstance(unset, list) or not all(isinstance(k, str) and k for k in unset):
        fail(str(path), UNSET, "an array of dotted keys of the parent (e.g. 'mapping.mu')", unset)
    parent_path = (path.parent / parent).resolve()
    if parent_path in (*children, path.resolve()):
        raise SpecError(f"{path}: key '{EXTENDS}' = {parent!r} extends itself (a cycle of specs)")
    merged = _merged(_resolved_table(parent_path, (*children, path.resolve())), table)
    for dotted in unset:
        *outer, last = dotted.split(".")
        holder = merged
        for key in outer:
            holder = holder.get(key) if isinstance(holder, dict) else None
        if not isinstance(holder, dict) or last not in holder:
            raise SpecError(f"{path}: key '{UNSET}' names {dotted!r}, which {parent} does not set")
        del holder[last]
    return merged


def _merged(parent: dict, child: dict) -> dict:
    """``child`` over ``parent``: tables merge key by key, anything else is replaced."""
    out = dict(parent)
    for key, value in child.items():
        both = isinstance(value, dict) and isinstance(out.get(key), dict)
        out[key] = _merged(out[key], value) if both else value
    return out
