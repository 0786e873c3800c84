"""Experiment specs: one TOML file per transfer experiment, validated on load.

A spec names the source and target tasks, how the source policy is learned,
the inter-task mapping, the transfer methods to compare with their settings
(``[methods.NAME]`` tables, built by ``tatl_mj.transfer.registry.resolve``), and named
presets of sample budgets and evaluation protocol. Validation calls the same
factories the workers use (``suite.describe``, ``make_regressor``, the method
constructors), so any unknown key (feature tables included), wrong type,
impossible value or setting that a choice ignores stops the load with a message
naming the file, the key path and what was expected. See ``tasks/*.toml``.

A user's own code is named by import path, ``"module:attribute"``, and imported
wherever the spec is used (here and in every worker): a side's ``domain``
(``tatl_mj.suite.domain``), and a ``[methods.NAME]`` table's ``method`` key, a
class built with the table's other settings (``tatl_mj.transfer.registry.resolve``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import re
import tomllib
import types
import typing
from pathlib import Path
from typing import Any

from tatl_mj.transfer import registry, roles
from tatl_mj.transfer.method import contract
from tatl_mj.validation import is_integer, is_number

SAMPLING_KINDS = ("episodes", "uniform")
SOURCE_LEARNERS = ("fqi", "q_iteration")
ALIGNMENT_DATA = ("episodes", "uniform")
# The name becomes a folder under --out: no separators, no "..", no hidden names.
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
    # Ridge of the linear regressor's least squares (default 1e-6); a larger one
    # keeps linear FQI from diverging on narrow RBFs (mountain car).
    ridge: float | None = None

    def regressor_spec(self) -> dict:
        spec: dict = {"kind": self.regressor, "features": self.features}
        if self.regressor == "linear":
            spec["ridge"] = 1e-6 if self.ridge is None else self.ridge
        return spec


@dataclasses.dataclass(frozen=True)
class MappingSpec:
    """The inter-task mapping chi (source -> target) and chi_plus (target -> source).

    ``identity`` (same state space); ``manifold_alignment`` (the paper's: learned
    without supervision from random-policy states; ``n_neighbors``, ``mu``);
    ``transition_alignment`` (this project's own: candidate state maps chosen
    by how well they explain the target's (s, a, s') transitions, dynamics
    consistency, in the spirit of Ammar et al.'s triplets but not their method;
    settings in ``transition``, see ``alignment.TransitionAlignment``); or ``affine``: a hand-coded
    chi(s_S) = matrix s_S + offset, ``matrix`` as rows (dT rows of dS numbers),
    optional ``offset`` (dT).

    Every map but the identity works in each task's mapping coordinates: its
    description's periodic coordinates measured from their ``angle_origin`` (the
    pendulum's angle from hanging), wrapped on the way in and out.
    ``source_data``: where the learned maps' source samples come from:
    ``"episodes"`` (random-policy episodes, like the target's; the default) or
    ``"uniform"`` (the source side's uniform box, which must then be its sampling).
    """

    kind: str = "identity"
    n_neighbors: int = 10
    mu: float = 1.0
    matrix: tuple[tuple[float, ...], ...] = ()
    offset: tuple[float, ...] = ()
    transition: dict = dataclasses.field(default_factory=dict)
    source_data: str = "episodes"


@dataclasses.dataclass(frozen=True)
class Preset:
    source_samples: int
    alignment_samples: int
    target_budgets: tuple[int, ...]
    evaluation_episodes: int
    evaluation_steps: int
    # The target task's fixed reference return under this evaluation protocol (a
    # controller or long-budget learner on the true system, never one of the
    # methods compared): normalised scores and the threshold are measured against it.
    reference_return: float | None = None
    # The seeds ``tatl run`` uses when none are given: ``seeds`` of them from
    # ``first_seed``. The paper preset's are held out (tuning used seeds 0-4).
    seeds: int = 2
    first_seed: int = 0
    # How many apprentice-predicted transitions a model-based learner (apprentice-fqi)
    # solves, where its method table leaves ``model_samples`` unset (None: the method's
    # own default). A compute budget, not target data: no real-target step is taken.
    model_samples: int | None = None


@dataclasses.dataclass(frozen=True)
class ExperimentSpec:
    name: str
    title: str
    paper_claim: str
    source: Side
    target: Side
    source_learning: Learner
    mapping: MappingSpec
    # method name -> its settings (``tatl_mj.transfer.registry``); run in this order.
    methods: dict
    presets: dict
    path: str = ""
    # A sweep over target conditions: one or two target task_kwargs, each a list of
    # values; ``conditions`` expands it into one experiment per combination.
    sweep: dict = dataclasses.field(default_factory=dict)
    # Set on a sweep's conditions: the swept values.
    condition: dict = dataclasses.field(default_factory=dict)
    # The name every random stream derives from (empty: ``name``). A sweep's conditions
    # take the sweep's, so each draws what the spec run alone with those task_kwargs
    # draws; a variant that changes only the mapping names its parent, so both draw the
    # same source data, target samples and evaluation starts (a paired comparison), and
    # their methods without a source are computed once (``tatl_mj.experiments.run.runner``).
    streams: str = ""
    # The strongest baseline per verdict question ({"final": NAME, "efficiency": NAME}),
    # chosen on the tuning seeds and frozen here (``verdicts.choose_best_baseline``): every
    # method that is not a baseline is compared with it, whichever seeds are reported.
    best_baseline: dict = dataclasses.field(default_factory=dict)
    # What the paper reports for this experiment, for the paper-vs-here table
    # (``tables.paper_table``): ``section`` (where in the paper) and ``numbers`` (its
    # figures, as text). Empty for the variants and sweeps, which the paper does not have.
    paper: dict = dataclasses.field(default_factory=dict)

    def preset(self, name: str) -> Preset:
        if name not in self.presets:
            raise SpecError(f"{self.path}: unknown preset {name!r}; valid presets: {sorted(self.presets)}")
        return self.presets[name]

    @property
    def stream_name(self) -> str:
        """The name every derived seed of this experiment starts from."""
        return self.streams or self.name


def _value_text(value: Any) -> str:
    return repr(value) if not isinstance(value, str) else value


def conditions(spec: ExperimentSpec) -> list[ExperimentSpec]:
    """The experiments a spec stands for: itself, or one per combination of its sweep's values,
    named ``NAME.PARAM-VALUE[.PARAM-VALUE]`` with those target task_kwargs, kept apart in
    their own records and resumable like any experiment."""
    if not spec.sweep:
        return [spec]
    names = list(spec.sweep)
    grids = [[]]  # type: list[list[tuple[str, Any]]]
    for name in names:
        grids = [g + [(name, v)] for g in grids for v in spec.sweep[name]]
    out = []
    for combo in grids:
        suffix = ".".join(f"{k}-{_value_text(v)}" for k, v in combo)
        target = dataclasses.replace(spec.target, task_kwargs={**spec.target.task_kwargs, **dict(combo)})
        name, condition, streams = f"{spec.name}.{suffix}", dict(combo), spec.stream_name
        out.append(dataclasses.replace(spec, name=name, target=target, sweep={}, condition=condition, streams=streams))
    return out


def _fail(path: str, key: str, expected: str, got: Any) -> typing.NoReturn:
    raise SpecError(f"{path}: key '{key}' must be {expected}, got {got!r}")


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
            _fail(path, key, "a finite number", value)
        return float(value)
    if hint is int:
        if not is_integer(value):
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


def _describe(spec: ExperimentSpec, side_name: str) -> Any:
    from tatl_mj import suite  # imports mujoco: only once the spec parsed

    p, side = spec.path, getattr(spec, side_name)
    try:
        tasks = suite.domain(side.domain).TASKS  # a built-in, or "module:attribute" imported and checked
    except suite.DomainError as error:
        raise SpecError(f"{p}: key '{side_name}.domain': {error}") from None
    if side.task not in tasks:
        raise SpecError(f"{p}: key '{side_name}.task' is {side.task!r}; valid tasks: {sorted(tasks)}")
    try:
        return suite.describe(side.domain, side.task, side.task_kwargs)
    except (TypeError, ValueError) as error:
        raise SpecError(f"{p}: key '{side_name}.task_kwargs': {error}") from None


def _check_side(spec: ExperimentSpec, side_name: str, description: Any) -> None:
    p, side = spec.path, getattr(spec, side_name)
    _choice(p, f"{side_name}.data.sampling", side.data.sampling, SAMPLING_KINDS)
    low, high = side.data.state_low, side.data.state_high
    if side.data.sampling == "uniform":
        if (
            len(low) != description.state_dim
            or len(high) != description.state_dim
            or any(lo >= hi for lo, hi in zip(low, high))
        ):
            raise SpecError(
                f"{p}: keys '{side_name}.data.state_low/state_high' must be arrays of {description.state_dim} "
                f"numbers ({', '.join(description.state_names)}) with low < high for uniform sampling, "
                f"got {list(low)} and {list(high)}"
            )
    elif low or high:
        raise SpecError(f"{p}: keys '{side_name}.data.state_low/state_high' apply to sampling 'uniform' only")
    if side.data.episode_steps <= 0:
        _fail(p, f"{side_name}.data.episode_steps", "a positive integer", side.data.episode_steps)


def _check_source_learning(spec: ExperimentSpec, description: Any) -> None:
    from tatl_mj.transfer import fqi

    p, learner = spec.path, spec.source_learning
    _choice(p, "source_learning.method", learner.method, SOURCE_LEARNERS)
    if not 0.0 <= learner.gamma < 1.0:
        _fail(p, "source_learning.gamma", "in [0, 1)", learner.gamma)
    if learner.method == "q_iteration":
        if description.known_model is None:
            raise SpecError(
                f"{p}: key 'source_learning.method' = 'q_iteration' needs a task with a known model; "
                f"{spec.source.domain}/{spec.source.task} has none (use 'fqi')"
            )
        return
    _choice(p, "source_learning.regressor", learner.regressor, fqi.REGRESSOR_KINDS)
    if learner.iterations <= 0:
        _fail(p, "source_learning.iterations", "a positive integer", learner.iterations)
    if learner.ridge is not None and learner.regressor != "linear":
        raise SpecError(f"{p}: key 'source_learning.ridge' applies to regressor 'linear' only")
    try:
        fqi.make_regressor(learner.regressor_spec(), description.state_dim)
    except (TypeError, ValueError) as error:
        raise SpecError(f"{p}: key 'source_learning.features': {error}") from None


def _check_mapping(spec: ExperimentSpec, source: Any, target: Any) -> None:
    from tatl_mj.transfer.mappings import MAPPINGS, transition_settings

    p, mapping = spec.path, spec.mapping
    _choice(p, "mapping.kind", mapping.kind, tuple(MAPPINGS))
    if mapping.kind == "identity" and source.state_dim != target.state_dim:
        raise SpecError(
            f"{p}: key 'mapping.kind' = 'identity' needs equal state sizes, got {source.state_dim} "
            f"(source) and {target.state_dim} (target)"
        )
    if mapping.kind == "affine":
        rows = mapping.matrix
        if len(rows) != target.state_dim or any(len(r) != source.state_dim for r in rows):
            _fail(
                p,
                "mapping.matrix",
                f"{target.state_dim} rows (target: {', '.join(target.state_names)}) of "
                f"{source.state_dim} numbers (source: {', '.join(source.state_names)})",
                rows,
            )
        if mapping.offset and len(mapping.offset) != len(rows):
            _fail(p, "mapping.offset", f"an array of {len(rows)} numbers (one per matrix row)", mapping.offset)
    elif mapping.matrix or mapping.offset:
        raise SpecError(f"{p}: keys 'mapping.matrix' and 'mapping.offset' apply only to kind 'affine'")
    if mapping.kind != "manifold_alignment" and (mapping.n_neighbors, mapping.mu) != (10, 1.0):
        raise SpecError(f"{p}: keys 'mapping.n_neighbors' and 'mapping.mu' apply only to kind 'manifold_alignment'")
    if mapping.transition:
        if mapping.kind != "transition_alignment":
            raise SpecError(f"{p}: key 'mapping.transition' applies only to kind 'transition_alignment'")
    if mapping.kind == "transition_alignment":
        try:
            transition_settings(mapping.transition)
        except (TypeError, ValueError) as error:
            raise SpecError(f"{p}: key 'mapping.transition': {error}") from None
    _choice(p, "mapping.source_data", mapping.source_data, ALIGNMENT_DATA)
    if mapping.source_data == "uniform" and spec.source.data.sampling != "uniform":
        raise SpecError(f"{p}: key 'mapping.source_data' = 'uniform' needs source.data.sampling = 'uniform'")
    if mapping.n_neighbors < 1:
        _fail(p, "mapping.n_neighbors", "a positive integer", mapping.n_neighbors)


def _check_methods(spec: ExperimentSpec, source: Any, target: Any) -> None:
    p = spec.path
    if not spec.methods:
        raise SpecError(f"{p}: at least one [methods.NAME] table is required; valid names: {sorted(registry.METHODS)}")
    for name, settings in spec.methods.items():
        if not isinstance(settings, dict):
            _fail(p, f"methods.{name}", "a table of settings", settings)
        for key in roles.PAIR_KEYS:
            other = settings.get(key)
            if key in settings and (not isinstance(other, str) or other not in spec.methods or other == name):
                _fail(
                    p, f"methods.{name}.{key}", f"the name of another method of this spec {sorted(spec.methods)}", other
                )
        try:
            check = contract(registry.resolve(name, settings)).check
            if check is not None:
                check(source, target)
        except (TypeError, ValueError) as error:
            raise SpecError(f"{p}: key 'methods.{name}': {error}") from None
    for key, value in spec.paper.items():
        if key not in ("section", "numbers"):
            raise SpecError(f"{p}: unknown key 'paper.{key}'; valid keys: ['numbers', 'section']")
        if not isinstance(value, str):
            _fail(p, f"paper.{key}", "a string", value)
    for question, baseline in spec.best_baseline.items():
        if question not in ("final", "efficiency"):
            raise SpecError(f"{p}: unknown key 'best_baseline.{question}'; valid keys: ['efficiency', 'final']")
        if not isinstance(baseline, str) or baseline not in spec.methods:
            _fail(p, f"best_baseline.{question}", f"a method of this spec {sorted(spec.methods)}", baseline)


def _check_sweep(spec: ExperimentSpec) -> None:
    p = spec.path
    if spec.condition:
        raise SpecError(f"{p}: key 'condition' is set by a sweep, not by a spec; use [sweep]")
    if not spec.sweep:
        return
    if len(spec.sweep) > 2:
        _fail(p, "sweep", "one or two target task_kwargs, each a list of values", sorted(spec.sweep))
    for name, values in spec.sweep.items():
        if name in spec.target.task_kwargs:
            raise SpecError(f"{p}: key 'sweep.{name}' is also fixed in target.task_kwargs; give it in one place")
        ok = (
            isinstance(values, (list, tuple))
            and values
            and all(isinstance(v, (int, float, str)) and not isinstance(v, bool) for v in values)
        )
        if not ok or len(set(values)) != len(values):
            _fail(p, f"sweep.{name}", "a non-empty list of distinct numbers or strings", values)
    from tatl_mj import suite

    for condition in conditions(spec):
        try:
            _describe(condition, "target")
            target = condition.target  # built once: the task's own checks of its kwargs
            suite.load(target.domain, target.task, task_kwargs={**target.task_kwargs, "random": 0})
        except SpecError as error:
            raise SpecError(f"{error} (in the sweep's condition {condition.condition})") from None
        except (TypeError, ValueError) as error:
            raise SpecError(f"{p}: key 'sweep': {error} (in the sweep's condition {condition.condition})") from None
        if not NAME_PATTERN.fullmatch(condition.name):
            _fail(p, "sweep", f"values that make a folder name ({NAME_PATTERN.pattern})", condition.name)


def _check(spec: ExperimentSpec) -> None:
    """Value checks that types alone cannot express, through the factories the workers use."""
    p = spec.path
    if not NAME_PATTERN.fullmatch(spec.name):
        _fail(p, "name", "1-100 of A-Z a-z 0-9 _ . - not starting with '.' or '-' (it names a folder)", spec.name)
    source, target = _describe(spec, "source"), _describe(spec, "target")
    _check_side(spec, "source", source)
    _check_side(spec, "target", target)
    _check_source_learning(spec, source)
    _check_mapping(spec, source, target)
    _check_methods(spec, source, target)
    _check_sweep(spec)
    if not spec.presets:
        raise SpecError(f"{p}: at least one [presets.NAME] table is required (e.g. smoke, paper)")
    for name, preset in spec.presets.items():
        key = f"presets.{name}"
        for field in ("source_samples", "alignment_samples", "evaluation_episodes", "evaluation_steps", "seeds"):
            if getattr(preset, field) <= 0:
                _fail(p, f"{key}.{field}", "a positive integer", getattr(preset, field))
        if preset.first_seed < 0:
            _fail(p, f"{key}.first_seed", "an integer >= 0", preset.first_seed)
        if preset.model_samples is not None and preset.model_samples <= 0:  # its type is checked on loading
            _fail(p, f"{key}.model_samples", "a positive integer", preset.model_samples)
        budgets = preset.target_budgets
        if not budgets or any(b <= 0 for b in budgets) or list(budgets) != sorted(set(budgets)):
            _fail(p, f"{key}.target_budgets", "a non-empty strictly increasing array of positive integers", budgets)


def methods_from_spec(spec: ExperimentSpec, preset: Preset, names: list[str] | None = None) -> dict[str, Any]:
    """Every method of the spec (or the ``names`` among them), built with its settings.

    Algorithm 2's increment (``batch``), where a method has one and the spec leaves
    it unset, is the preset's smallest target budget; a model-based learner's
    ``model_samples``, likewise, is the preset's where it sets one.
    """
    chosen = list(spec.methods) if names is None else names
    out = {}
    for name in chosen:
        settings = dict(spec.methods.get(name, {}))
        if roles.plugin_path(settings) is None:
            known = registry.settings_of(roles.base_of(name, settings))
            if "batch" in known and settings.get("batch") is None:
                settings["batch"] = min(preset.target_budgets)
            if "model_samples" in known and "model_samples" not in settings and preset.model_samples is not None:
                settings["model_samples"] = preset.model_samples
        out[name] = registry.resolve(name, settings)
    return out


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
        _fail(str(path), EXTENDS, "the path of a parent spec, relative to this one", parent)
    if not isinstance(unset, list) or not all(isinstance(k, str) and k for k in unset):
        _fail(str(path), UNSET, "an array of dotted keys of the parent (e.g. 'mapping.mu')", unset)
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


def spec_to_dict(spec: ExperimentSpec) -> dict:
    """A JSON-able copy of the spec (for summary.json)."""
    return dataclasses.asdict(spec)


NOT_CONTENT = ("path", "title", "paper_claim", "paper", "best_baseline")
"""Spec fields that cannot change a record: where it was read from, its prose, the paper's
numbers, and the baseline its verdicts are read against (frozen after the tuning runs)."""


def content_hash(spec: ExperimentSpec | dict, preset: str | None = None) -> str:
    """The SHA-256 of a spec's content: its parsed, resolved settings (:func:`spec_to_dict`, or
    that dict as summary.json keeps it, but :data:`NOT_CONTENT`) as canonical JSON, not the
    file's bytes, so a reformatted spec, or one that reaches the same settings another way,
    keeps it. With ``preset`` (one the spec has), the other presets are left out: records of
    that preset depend on none of them."""
    table = spec_to_dict(spec) if isinstance(spec, ExperimentSpec) else dict(spec)
    table = {k: v for k, v in table.items() if k not in NOT_CONTENT}
    if preset is not None:
        table["presets"] = {preset: table["presets"][preset]}
    text = json.dumps(table, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


def dynamics_versions(spec: ExperimentSpec) -> dict[str, int]:
    """The dynamics version of each task the spec uses, by ``domain/task`` (source, then target)."""
    from tatl_mj import suite

    return {
        f"{side.domain}/{side.task}": suite.describe(side.domain, side.task, side.task_kwargs).dynamics_version
        for side in (spec.source, spec.target)
    }
