"""A spec's value checks, beyond what its types say, through the factories the workers use
(``suite.describe``, ``make_regressor``, the method constructors), each failure a SpecError
naming the file, the key and what was expected."""

from __future__ import annotations

from typing import Any

from tatl_mj.experiments.spec.schema import (
    ALIGNMENT_DATA,
    NAME_PATTERN,
    SAMPLING_KINDS,
    SOURCE_LEARNERS,
    ExperimentSpec,
    SpecError,
    fail,
)
from tatl_mj.experiments.spec.sweep import conditions
from tatl_mj.transfer import registry, roles
from tatl_mj.transfer.method import contract


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
        fail(p, f"{side_name}.data.episode_steps", "a positive integer", side.data.episode_steps)


def _check_source_learning(spec: ExperimentSpec, description: Any) -> None:
    from tatl_mj.transfer import fqi

    p, learner = spec.path, spec.source_learning
    _choice(p, "source_learning.method", learner.method, SOURCE_LEARNERS)
    if not 0.0 <= learner.gamma < 1.0:
        fail(p, "source_learning.gamma", "in [0, 1)", learner.gamma)
    if learner.method == "q_iteration":
        if description.known_model is None:
            raise SpecError(
                f"{p}: key 'source_learning.method' = 'q_iteration' needs a task with a known model; "
                f"{spec.source.domain}/{spec.source.task} has none (use 'fqi')"
            )
        return
    _choice(p, "source_learning.regressor", learner.regressor, fqi.REGRESSOR_KINDS)
    if learner.iterations <= 0:
        fail(p, "source_learning.iterations", "a positive integer", learner.iterations)
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
            fail(
                p,
                "mapping.matrix",
                f"{target.state_dim} rows (target: {', '.join(target.state_names)}) of "
                f"{source.state_dim} numbers (source: {', '.join(source.state_names)})",
                rows,
            )
        if mapping.offset and len(mapping.offset) != len(rows):
            fail(p, "mapping.offset", f"an array of {len(rows)} numbers (one per matrix row)", mapping.offset)
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
        fail(p, "mapping.n_neighbors", "a positive integer", mapping.n_neighbors)


def _check_methods(spec: ExperimentSpec, source: Any, target: Any) -> None:
    p = spec.path
    if not spec.methods:
        raise SpecError(f"{p}: at least one [methods.NAME] table is required; valid names: {sorted(registry.METHODS)}")
    for name, settings in spec.methods.items():
        if not isinstance(settings, dict):
            fail(p, f"methods.{name}", "a table of settings", settings)
        for key in roles.PAIR_KEYS:
            if key in settings and not _names_other_methods(spec, name, settings[key], many=key == "ablation"):
                what = "the name of another method of this spec"
                if key == "ablation":
                    what += ", or a list of such names without repeats,"
                fail(p, f"methods.{name}.{key}", f"{what} {sorted(spec.methods)}", settings[key])
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
            fail(p, f"paper.{key}", "a string", value)
    for question, baseline in spec.best_baseline.items():
        if question not in ("final", "efficiency"):
            raise SpecError(f"{p}: unknown key 'best_baseline.{question}'; valid keys: ['efficiency', 'final']")
        if not isinstance(baseline, str) or baseline not in spec.methods:
            fail(p, f"best_baseline.{question}", f"a method of this spec {sorted(spec.methods)}", baseline)


def _names_other_methods(spec: ExperimentSpec, name: str, value: Any, many: bool) -> bool:
    """Whether a pair key's value names other methods of the spec: one name, or (``many``, the
    ``ablation`` key) a non-empty list of distinct names."""
    names = value if many and isinstance(value, list) and value else [value]
    return len(set(map(repr, names))) == len(names) and all(
        isinstance(other, str) and other in spec.methods and other != name for other in names
    )


def _check_sweep(spec: ExperimentSpec) -> None:
    p = spec.path
    if spec.condition:
        raise SpecError(f"{p}: key 'condition' is set by a sweep, not by a spec; use [sweep]")
    if not spec.sweep:
        return
    if len(spec.sweep) > 2:
        fail(p, "sweep", "one or two target task_kwargs, each a list of values", sorted(spec.sweep))
    for name, values in spec.sweep.items():
        if name in spec.target.task_kwargs:
            raise SpecError(f"{p}: key 'sweep.{name}' is also fixed in target.task_kwargs; give it in one place")
        ok = (
            isinstance(values, (list, tuple))
            and values
            and all(isinstance(v, (int, float, str)) and not isinstance(v, bool) for v in values)
        )
        if not ok or len(set(values)) != len(values):
            fail(p, f"sweep.{name}", "a non-empty list of distinct numbers or strings", values)
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
            fail(p, "sweep", f"values that make a folder name ({NAME_PATTERN.pattern})", condition.name)


def validate(spec: ExperimentSpec) -> None:
    """Value checks that types alone cannot express, through the factories the workers use."""
    p = spec.path
    if not NAME_PATTERN.fullmatch(spec.name):
        fail(p, "name", "1-100 of A-Z a-z 0-9 _ . - not starting with '.' or '-' (it names a folder)", spec.name)
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
                fail(p, f"{key}.{field}", "a positive integer", getattr(preset, field))
        if preset.first_seed < 0:
            fail(p, f"{key}.first_seed", "an integer >= 0", preset.first_seed)
        if preset.model_samples is not None and preset.model_samples <= 0:  # its type is checked on loading
            fail(p, f"{key}.model_samples", "a positive integer", preset.model_samples)
        budgets = preset.target_budgets
        if not budgets or any(b <= 0 for b in budgets) or list(budgets) != sorted(set(budgets)):
            fail(p, f"{key}.target_budgets", "a non-empty strictly increasing array of positive integers", budgets)
