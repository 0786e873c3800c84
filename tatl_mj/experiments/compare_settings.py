"""``tatl compare --settings FILE``: per-experiment constructor settings for a user's plug-ins.

A plug-in named with ``--methods module:Class`` is built without arguments; a settings file
gives it other settings per experiment, without touching the shipped specs (whose content
hashes the reference checks)::

    [one-step-match.grid_to_windy]     # [METHOD.EXPERIMENT]: METHOD a --methods name
    basis = "one_hot"                  # keyword arguments of its constructor

EXPERIMENT is an experiment the comparison runs, or a spec's name for every condition of
its sweep. An experiment without a table gets the method as ``--methods`` built it. Each
table is checked before anything runs, through the method's declared ``constraints``
(``tatl_mj.validation``) and its constructor: an unknown method, experiment or setting, or a
value its constraints refuse, stops the comparison in one line naming the file and the table.
The file is copied into the comparison's folder and its SHA-256 recorded in compare.json.
"""

from __future__ import annotations

import dataclasses
import hashlib
import tomllib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from tatl_mj.experiments.spec import ExperimentSpec
from tatl_mj.validation import checked_settings

FILE = "settings.toml"
"""The settings file's name in a comparison's folder."""


@dataclasses.dataclass(frozen=True)
class Settings:
    """A read settings file: its path, its bytes' SHA-256 and its tables by method and experiment."""

    path: Path
    sha256: str
    tables: dict[str, dict[str, dict[str, Any]]]


def read(path: str | Path) -> Settings:
    """The file's tables; ValueError (one line) where it is not TOML of ``[METHOD.EXPERIMENT]`` tables."""
    path = Path(path)
    try:
        data = path.read_bytes()
        parsed = tomllib.loads(data.decode())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as error:
        raise ValueError(f"--settings {path}: cannot read it as TOML ({error})") from None
    for method, table in parsed.items():
        loose = sorted(k for k, v in table.items() if not isinstance(v, dict)) if isinstance(table, dict) else [method]
        if loose:
            raise ValueError(
                f"--settings {path}: {method}.{loose[0]} is not in a table of one experiment; write "
                f"[{method}.EXPERIMENT] then its settings"
            )
    return Settings(path=path, sha256=hashlib.sha256(data).hexdigest(), tables=parsed)


def _built(obj: Any, settings: dict[str, Any], where: str) -> Any:
    """``obj``'s class with ``settings`` (checked through its constraints), under ``obj``'s name."""
    cls = type(obj)
    if "name" in settings:
        raise ValueError(f"{where}: 'name' is not a setting; the method keeps its name {obj.name!r}")
    try:
        given = checked_settings(cls, settings)
        built = dataclasses.replace(obj, **given) if dataclasses.is_dataclass(obj) else cls(**given)
    except TypeError as error:
        fields = (
            [f.name for f in dataclasses.fields(obj) if f.init and f.name != "name"]
            if dataclasses.is_dataclass(obj)
            else []
        )
        known = f" (its settings: {fields})" if fields else ""
        raise ValueError(f"{where}: {cls.__name__}(**settings) failed: {error}{known}") from None
    except ValueError as error:
        raise ValueError(f"{where}: {error}") from None
    if getattr(built, "name", None) != obj.name:
        raise ValueError(f"{where}: built with these settings it is named {built.name!r}, not {obj.name!r}")
    return built


def apply(
    settings: Settings, methods: Mapping[str, Any], specs: Sequence[ExperimentSpec], parents: Mapping[str, str]
) -> tuple[dict[str, Any], dict[str, dict[str, dict[str, Any]]]]:
    """The user's methods with the file's settings: each one it names as {experiment: method
    object} (every experiment of ``specs``), the others as they are; and the settings each
    experiment got, by method. ``parents``: experiment -> the name of the spec it came from."""
    where = f"--settings {settings.path}"
    names = sorted(n for n, obj in methods.items() if obj is not None)
    experiments = [s.name for s in specs]
    out, used = dict(methods), {}
    for method, tables in settings.tables.items():
        if method not in names:
            raise ValueError(f"{where}: [{method}] names none of your plug-ins ({names})")
        unknown = sorted(set(tables) - set(experiments) - set(parents.values()))
        if unknown:
            raise ValueError(
                f"{where}: [{method}.{unknown[0]}] names no experiment of this comparison (its experiments: "
                f"{experiments})"
            )
        per: dict[str, Any] = {}
        for experiment in experiments:
            table = tables.get(experiment, tables.get(parents[experiment]))
            if table is None:
                per[experiment] = methods[method]
                continue
            label = experiment if experiment in tables else parents[experiment]
            per[experiment] = _built(methods[method], dict(table), f"{where}: [{method}.{label}]")
            used.setdefault(method, {})[experiment] = table
        out[method] = per
    return out, used


__all__ = ["FILE", "Settings", "apply", "read"]
