"""Experiment specs: one TOML file per transfer experiment, validated on load.

A spec names the source and target tasks, how the source policy is learned,
the inter-task mapping, the apprentice, the target learners of the baselines,
the evaluation protocol and named presets of sample budgets. Any unknown key,
wrong type or impossible value stops the load with a message naming the file,
the key and what was expected. See ``tasks/*.toml`` for the five experiments.
"""

from __future__ import annotations

import dataclasses
import math
import re
import tomllib
import typing
from pathlib import Path
from typing import Any

SAMPLING_KINDS = ("episodes", "uniform")
SOURCE_LEARNERS = ("fqi", "q_iteration")
MAPPING_KINDS = ("identity", "manifold_alignment", "affine")
REGRESSORS = ("linear", "extra_trees")
# [robustness] The name becomes a folder under --out: no separators, no "..", no hidden names.
NAME_PATTERN = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,99}")


class SpecError(ValueError):
    """A malformed experiment spec; the message names the file and the key."""


@dataclasses.dataclass(frozen=True)
class Data:
    """How random-policy transitions of one side are collected.

    ``episodes``: episodes from the task's own start distribution, uniformly random
    actions. ``uniform``: one-step transitions from states drawn uniformly in
    [state_low, state_high] with random actions (the classic FQI batch).
    """

    sampling: str = "episodes"
    state_low: tuple[float, ...] = ()
    state_high: tuple[float, ...] = ()
    episode_steps: int = 200


@dataclasses.dataclass(frozen=True)
class Side:
    domain: str
    task: str
    task_kwargs: dict = dataclasses.field(default_factory=dict)
    data: Data = Data()


@dataclasses.dataclass(frozen=True)
class Learner:
    """A value-function learner: FQI (or exact Q-iteration for a known model)."""

    method: str = "fqi"
    features: dict = dataclasses.field(default_factory=lambda: {"kind": "linear"})
    regressor: str = "linear"
    gamma: float = 0.95
    iterations: int = 20
    # Ridge of the linear regressor's least squares; a larger one keeps linear
    # FQI from diverging on narrow RBFs (mountain car).
    ridge: float = 1e-6


@dataclasses.dataclass(frozen=True)
class Mapping:
    """The inter-task mapping chi (source -> target) and chi_plus (target -> source).

    ``identity`` (same state space), ``manifold_alignment`` (learned without
    supervision from random-policy samples; ``n_neighbors``, ``mu``), or
    ``affine``: a hand-coded chi(s_S) = matrix s_S + offset, with ``matrix``
    given as rows (dT rows of dS numbers) and an optional ``offset`` (dT).
    """

    kind: str = "identity"
    n_neighbors: int = 10
    mu: float = 1.0
    matrix: tuple[tuple[float, ...], ...] = ()
    offset: tuple[float, ...] = ()


@dataclasses.dataclass(frozen=True)
class ApprenticeSpec:
    features: dict = dataclasses.field(default_factory=lambda: {"kind": "linear"})
    # Algorithm 2 stops once |U_M - U_Mhat| <= zeta * (|U_M| + 1e-9), a relative gap.
    zeta: float = 0.1
    adaptive_actions: tuple[float, ...] = ()
    # Ridge of the apprentice's least squares; > 0 where the basis cannot be
    # full rank on small budgets (one-hot cells the random walk never visited).
    ridge: float = 0.0


@dataclasses.dataclass(frozen=True)
class Preset:
    source_samples: int
    alignment_samples: int
    target_budgets: tuple[int, ...]
    evaluation_episodes: int
    evaluation_steps: int


@dataclasses.dataclass(frozen=True)
class ExperimentSpec:
    name: str
    title: str
    paper_claim: str
    source: Side
    target: Side
    source_learning: Learner
    mapping: Mapping
    apprentice: ApprenticeSpec
    target_learning: Learner
    presets: dict
    path: str = ""

    def preset(self, name: str) -> Preset:
        if name not in self.presets:
            raise SpecError(f"{self.path}: unknown preset {name!r}; valid presets: {sorted(self.presets)}")
        return self.presets[name]


def _fail(path: str, key: str, expected: str, got: Any) -> typing.NoReturn:
    raise SpecError(f"{path}: key '{key}' must be {expected}, got {got!r}")


def _convert(value: Any, hint: Any, path: str, key: str) -> Any:
    """Checks ``value`` against a type hint; converts lists to tuples, ints to floats."""
    origin = typing.get_origin(hint)
    if dataclasses.is_dataclass(hint):
        return _build(hint, value, path, key)
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            _fail(path, key, "a finite number", value)
        return float(value)
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            _fail(path, key, "an integer", value)
        return value
    if hint is str:
        if not isinstance(value, str):
            _fail(path, key, "a string", value)
        return value
    if hint is dict or origin is dict:
        if not isinstance(value, dict):
            _fail(path, key, "a table", value)
        return value
    if origin is tuple:
        if not isinstance(value, list):
            _fail(path, key, "an array", value)
        item = typing.get_args(hint)[0]
        return tuple(_convert(v, item, path, f"{key}[{i}]") for i, v in enumerate(value))
    raise TypeError(f"unsupported spec type {hint!r}")  # a bug in this module, not in the spec


def _build(cls: type, table: Any, path: str, prefix: str) -> Any:
    if not isinstance(table, dict):
        _fail(path, prefix, "a table", table)
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


def _choice(path: str, key: str, value: str, valid: tuple[str, ...]) -> None:
    if value not in valid:
        raise SpecError(f"{path}: key '{key}' is {value!r}; valid choices: {list(valid)}")


def _check(spec: ExperimentSpec) -> None:
    """Value checks that types alone cannot express."""
    from tatl_mj import suite  # imports mujoco: only once the spec parsed

    p = spec.path
    if not NAME_PATTERN.fullmatch(spec.name):  # [robustness]
        _fail(p, "name", "1-100 of A-Z a-z 0-9 _ . - not starting with '.' or '-' (it names a folder)", spec.name)
    for side_name in ("source", "target"):
        side: Side = getattr(spec, side_name)
        if side.domain not in suite.DOMAINS:
            raise SpecError(f"{p}: key '{side_name}.domain' is {side.domain!r}; valid domains: {sorted(suite.DOMAINS)}")
        tasks = suite.DOMAINS[side.domain].TASKS
        if side.task not in tasks:
            raise SpecError(f"{p}: key '{side_name}.task' is {side.task!r}; valid tasks: {sorted(tasks)}")
        _choice(p, f"{side_name}.data.sampling", side.data.sampling, SAMPLING_KINDS)
        if side.data.sampling == "uniform":
            low, high = side.data.state_low, side.data.state_high
            if not low or len(low) != len(high) or any(lo >= hi for lo, hi in zip(low, high)):
                raise SpecError(
                    f"{p}: keys '{side_name}.data.state_low/state_high' must be equal-length arrays "
                    f"with low < high for uniform sampling, got {low} and {high}"
                )
        if side.data.episode_steps <= 0:
            _fail(p, f"{side_name}.data.episode_steps", "a positive integer", side.data.episode_steps)
    for name in ("source_learning", "target_learning"):
        learner: Learner = getattr(spec, name)
        _choice(p, f"{name}.method", learner.method, SOURCE_LEARNERS if name == "source_learning" else ("fqi",))
        _choice(p, f"{name}.regressor", learner.regressor, REGRESSORS)
        if not 0.0 <= learner.gamma < 1.0:
            _fail(p, f"{name}.gamma", "in [0, 1)", learner.gamma)
        if learner.iterations <= 0:
            _fail(p, f"{name}.iterations", "a positive integer", learner.iterations)
        if learner.ridge < 0:
            _fail(p, f"{name}.ridge", "a number >= 0", learner.ridge)
    if spec.source_learning.method == "q_iteration" and spec.source.domain != "gridworld":
        raise SpecError(f"{p}: key 'source_learning.method' = 'q_iteration' needs a known model (domain 'gridworld')")
    _choice(p, "mapping.kind", spec.mapping.kind, MAPPING_KINDS)
    if spec.mapping.kind == "affine":
        rows = spec.mapping.matrix
        if not rows or len({len(r) for r in rows}) != 1 or not rows[0]:
            _fail(p, "mapping.matrix", "a non-empty array of equal-length rows for kind 'affine'", rows)
        if spec.mapping.offset and len(spec.mapping.offset) != len(rows):
            _fail(p, "mapping.offset", f"an array of {len(rows)} numbers (one per matrix row)", spec.mapping.offset)
    elif spec.mapping.matrix or spec.mapping.offset:
        raise SpecError(f"{p}: keys 'mapping.matrix' and 'mapping.offset' apply only to kind 'affine'")
    if spec.mapping.n_neighbors < 1:
        _fail(p, "mapping.n_neighbors", "a positive integer", spec.mapping.n_neighbors)
    if spec.apprentice.zeta <= 0:
        _fail(p, "apprentice.zeta", "a number > 0", spec.apprentice.zeta)
    if spec.apprentice.ridge < 0:
        _fail(p, "apprentice.ridge", "a number >= 0", spec.apprentice.ridge)
    if not spec.presets:
        raise SpecError(f"{p}: at least one [presets.NAME] table is required (e.g. smoke, paper)")
    for name, preset in spec.presets.items():
        key = f"presets.{name}"
        for field in ("source_samples", "alignment_samples", "evaluation_episodes", "evaluation_steps"):
            if getattr(preset, field) <= 0:
                _fail(p, f"{key}.{field}", "a positive integer", getattr(preset, field))
        budgets = preset.target_budgets
        if not budgets or any(b <= 0 for b in budgets) or list(budgets) != sorted(set(budgets)):
            _fail(p, f"{key}.target_budgets", "a non-empty strictly increasing array of positive integers", budgets)


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
    _check(skeleton)
    return skeleton


def load_spec(path: str | Path) -> ExperimentSpec:
    """Reads and validates one experiment spec (TOML)."""
    path = Path(path)
    try:
        table = tomllib.loads(path.read_text(encoding="utf-8"))
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
    return parse_spec(table, str(path))


def spec_to_dict(spec: ExperimentSpec) -> dict:
    """A JSON-able copy of the spec (for summary.json)."""
    return dataclasses.asdict(spec)

