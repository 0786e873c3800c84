"""The batch runner: work units over a local process pool or a Ray cluster, resumable.

Two kinds of work unit. A source unit, per (experiment, seed): learn the
source policy and the mapping and draw the target data (cached on disk and
reused by every method). A method unit, per (experiment, seed, method): one
method's learning curve, which starts as soon as its source unit is done, in
the same pool. Workers return their results; only this process writes, each
record atomically, so a crash or a kill loses no finished unit and a rerun of
the same command resumes where it stopped. A failing unit is reported
(traceback in DIR/failures/) and does not take the others down; once every
other unit has finished and the summary is written, :func:`run` raises
:class:`RunFailed`, so a run with a failed unit never looks like a success.

Every unit computes on one BLAS/OpenMP thread and one MuJoCo thread
(:func:`determinism.one_thread`), as a one-CPU Ray task does, so its record depends
neither on the executor nor on the machine's core count.
"""

from __future__ import annotations

import collections
import dataclasses
import json
import pickle
import platform
import sys
import time
import traceback
from importlib import metadata
from pathlib import Path
from typing import Any, Callable, Iterable

from tqdm import tqdm

from tatl_mj import sampling
from tatl_mj.experiments.results import summary as summary_mod
from tatl_mj.experiments.results import verdicts
from tatl_mj.experiments.results.records import (
    SCHEMA_VERSION,
    SOURCE_UNIT,
    RecordError,
    RunDirectory,
    load_blob,
    read_json,
    read_record,
    write_atomic,
    write_json,
)
from tatl_mj.experiments.run import determinism, executors, lock, method_unit, rehearsal, sides, source_unit
from tatl_mj.experiments.run.kernels import kernels
from tatl_mj.experiments.spec import (
    NOT_CONTENT,
    ExperimentSpec,
    conditions,
    dynamics_versions,
    methods_from_spec,
    spec_to_dict,
)
from tatl_mj.transfer import fit_time, registry
from tatl_mj.transfer.method import contract


class MethodError(ValueError):
    """A method asked for that a spec cannot run (raised before any work starts)."""


class RunFolderError(ValueError):
    """``--out`` holds a run that this one cannot join (another preset); raised before any work."""


class RunFailed(RuntimeError):
    """Units failed (or were skipped because their source unit failed).

    Raised by :func:`run` only after every other unit finished, its record
    written, and the summary written; ``summary`` is what :func:`run` would have
    returned (its ``failures`` lists each unit), ``failed`` and ``skipped`` count
    them, ``failures_dir`` holds the tracebacks. A rerun of the same command
    retries exactly these units.
    """

    def __init__(self, summary: dict, failed: int, skipped: int, total: int, failures_dir: Path) -> None:
        self.summary, self.failed, self.skipped, self.total = summary, failed, skipped, total
        self.failures_dir = failures_dir
        units = failed + skipped
        parts = [f"{failed} failed"] + ([f"{skipped} skipped as their source unit failed"] if skipped else [])
        super().__init__(
            f"{units} of {total} work unit{'s' if total != 1 else ''} did not finish ({', '.join(parts)}); "
            f"tracebacks in {failures_dir}/; rerun the same command to retry them"
        )


@dataclasses.dataclass(frozen=True)
class Unit:
    experiment: str
    seed: int
    name: str  # "source" or a method name

    def __str__(self) -> str:
        return f"{self.experiment}/seed{self.seed}/{self.name}"


def work(
    spec: ExperimentSpec,
    preset_name: str,
    unit: Unit,
    source_blob: bytes | None,
    transfer: Any = None,
) -> dict:
    """Runs one unit in a worker; never raises (a failure is returned as data).

    ``transfer`` is the method object for a method unit (a user's own
    ``TransferMethod``, or None for the spec's built-in of that name).
    """
    start = time.perf_counter()
    try:
        with determinism.one_thread():  # workers run in parallel; records must not see the core count
            return _work(spec, preset_name, unit, source_blob, transfer, start)
    except Exception:  # noqa: BLE001 - a unit's failure must not stop the batch
        return {"error": traceback.format_exc()}


def _work(
    spec: ExperimentSpec, preset_name: str, unit: Unit, source_blob: bytes | None, transfer: Any, start: float
) -> dict:
    """:func:`work`'s unit, which may raise."""
    preset = spec.preset(preset_name)
    substeps, fits = sampling.physics_substeps(), fit_time.fqi_seconds()
    if unit.name == SOURCE_UNIT:
        # source_blob here: the artefacts of an experiment that differs only in its mapping.
        shared = load_blob(source_blob) if source_blob is not None else None
        artifacts = source_unit.learn_source(spec, preset, unit.seed, shared)
        blob = pickle.dumps(artifacts, protocol=pickle.HIGHEST_PROTOCOL)
        record = {
            "experiment": spec.name,
            "seed": unit.seed,
            "random_return": artifacts.random_return,
            "source_samples": artifacts.source_samples,
            "mapping_source_samples": artifacts.mapping_source_samples,
            "mapping_target_samples": artifacts.mapping_target_samples,
            "mapping": artifacts.mapping_record,
            "timings": artifacts.timings,
        }
    else:
        artifacts = load_blob(source_blob)
        blob = None
        record = method_unit.run_method(spec, preset, unit.seed, unit.name, artifacts, transfer=transfer)
    record["kernels"] = kernels()  # what it depends on besides its settings and seed
    record["dynamics"] = dynamics_versions(spec)  # and the versions of its tasks' dynamics
    record["wall_s"] = time.perf_counter() - start
    record["fqi_s"] = fit_time.fqi_seconds() - fits  # a cost, like wall_s: its part in FQI's fits
    # A cost, like wall_s: the MuJoCo substeps this unit took, by task.
    record["physics_substeps"] = {
        key: n - substeps.get(key, 0) for key, n in sampling.physics_substeps().items() if n > substeps.get(key, 0)
    }
    return {"record": record, "blob": blob}


# --- the run ----------------------------------------------------------------------


def _versions() -> dict:
    names = ("tatl-mj", "mujoco", "dm-control", "numpy", "scipy", "scikit-learn")
    out = {"python": sys.version.split()[0], "platform": platform.platform()}
    for name in names:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def _kernel_counts(run_dir: RunDirectory, units: list[Unit]) -> dict[str, int]:
    """How many of the run's records each set of arithmetic kernels computed (a run resumed
    elsewhere, or a Ray cluster of unlike nodes, can mix them)."""
    counts: collections.Counter[str] = collections.Counter()
    for unit in units:
        try:
            record = read_record(run_dir.record_path(unit.experiment, unit.seed, unit.name))
        except (OSError, ValueError):
            continue  # not finished: named among the failures
        counts[record["kernels"]] += 1
    return dict(counts)


def _check_manifest(run_dir: RunDirectory, preset: str, specs: list[ExperimentSpec]) -> None:
    """Refuses to mix presets in one folder (records of different budgets would blend)."""
    manifest = {"preset": preset}
    if run_dir.manifest.exists():
        old = read_json(run_dir.manifest)
        if old.get("preset") != preset:
            raise RunFolderError(
                f"{run_dir.root} holds a run with preset {old.get('preset')!r}; use another --out for preset {preset!r}"
            )
        experiments = sorted(set(old.get("experiments", [])) | {s.name for s in specs})
    else:
        experiments = sorted(s.name for s in specs)
    write_json(run_dir.manifest, {**manifest, "experiments": experiments})


def _plan(
    specs: list[ExperimentSpec],
    preset: str,
    seeds: list[int],
    methods: Iterable[str] | dict[str, Any] | None,
) -> tuple[list[Unit], dict[str, Any]]:
    """Every unit of the run, sources first, and the user's method objects by name.

    ``methods`` None: each spec's own ``[methods]``; names: those built-ins (with
    the spec's settings where it has them); a dict: name -> method object (None
    for such a built-in).
    """
    given = methods.items() if isinstance(methods, dict) else []
    custom = {k: _resolved(v, k) for k, v in given if v is not None}
    units = []
    for spec in specs:
        names = list(spec.methods) if methods is None else list(methods)
        for name in names:
            if name not in custom and name not in registry.METHODS and name not in spec.methods:
                raise MethodError(
                    f"unknown method {name!r} for {spec.name}; valid methods: {list(spec.methods)} "
                    "(the methods its spec lists; other built-ins run with their default settings, "
                    "plug-ins as module:Class)"
                )
            if name not in custom and name not in spec.methods:
                _check_applies(spec, name)
        units += [Unit(spec.name, seed, name) for seed in seeds for name in [SOURCE_UNIT, *names]]
    return units, custom


def check_methods(
    specs: list[ExperimentSpec],
    preset: str,
    methods: Iterable[str] | dict[str, Any] | None,
    seed: int = 0,
    rehearse: bool = False,
) -> None:
    """:class:`MethodError` where a method asked for cannot run on one of ``specs`` (sweeps
    expanded), and with ``rehearse`` where a user's policy answers other than its target takes:
    what :func:`run` checks first, for a caller that writes before it runs."""
    expanded = [c for spec in specs for c in conditions(spec)]
    _, custom = _plan(expanded, preset, [seed], methods)
    if rehearse:
        check_policies(expanded, preset, custom, seed)


def check_policies(specs: list[ExperimentSpec], preset: str, custom: dict[str, Any], seed: int = 0) -> None:
    """:class:`MethodError` where a user's policy, learned on a tiny problem of a spec's tasks,
    answers other than its target takes (``rehearsal.rehearse``); before any source work."""
    try:
        rehearsal.rehearse(specs, preset, custom, seed)
    except rehearsal.RehearsalError as error:
        raise MethodError(str(error)) from None


def _resolved(method: Any, name: str) -> Any:
    """A user's method object checked against the contract, or {experiment: such an object}
    where it has settings of its own per experiment (``tatl compare --settings``)."""
    if isinstance(method, dict):
        return {experiment: registry.resolve(obj, label=name) for experiment, obj in method.items()}
    return registry.resolve(method, label=name)


# What a method unit's record may depend on besides its method and seed: everything in
# its spec but the experiment's names, its mapping and its other methods.
_NOT_SHARED = (*NOT_CONTENT, "name", "mapping", "methods", "streams")


def _experiment_key(spec: ExperimentSpec, preset: str) -> list:
    """What an experiment's units may depend on besides their own settings and seed."""
    rest = {k: v for k, v in spec_to_dict(spec).items() if k not in _NOT_SHARED}
    return [spec.stream_name, preset, rest]


def _share_key(spec: ExperimentSpec, preset: str, unit: Unit, custom: dict[str, Any], base: list) -> str | None:
    """Equal for units whose work is shared: source units of experiments that draw the same
    streams and differ only in their mapping and methods (the source Q, target samples and
    random return are one computation; each learns its own mapping), and in those a method
    without a source (``uses_source`` False: the problem withholds the source Q, mapping and
    source simulator), whose record is the same but its ``experiment``; None for any other.
    ``base``: the experiment's :func:`_experiment_key`."""
    if unit.name == SOURCE_UNIT:
        return json.dumps([*base, unit.seed], sort_keys=True, default=repr)
    if unit.name in custom:
        return None
    transfer = methods_from_spec(spec, spec.preset(preset), [unit.name])[unit.name]
    if contract(transfer).uses_source:
        return None
    parts = [*base, unit.seed, unit.name, spec.methods.get(unit.name), repr(transfer)]
    return json.dumps(parts, sort_keys=True, default=repr)


def _shared(
    specs: dict[str, ExperimentSpec], preset: str, units: list[Unit], custom: dict[str, Any]
) -> list[list[Unit]]:
    """The groups (two or more) of units that share work (:func:`_share_key`), in run order."""
    bases = {name: _experiment_key(spec, preset) for name, spec in specs.items()}
    groups: dict[str, list[Unit]] = {}
    for unit in units:
        key = _share_key(specs[unit.experiment], preset, unit, custom, bases[unit.experiment])
        if key is not None:
            groups.setdefault(key, []).append(unit)
    return [group for group in groups.values() if len(group) > 1]


def shared_record(record: dict, unit: Unit, origin: Unit) -> dict:
    """``origin``'s record as ``unit``'s: the same curve, marked as shared, with none of the
    work (its wall time, FQI time, substeps and phase timings are the origin's alone)."""
    curve = [{**point, "learn_s": 0.0, "evaluate_s": 0.0, "premises_s": 0.0} for point in record["curve"]]
    first = record.get("shared_from", str(origin))
    if first == str(unit):  # its own record was lost and comes back from a copy of it
        first = str(origin)
    return {
        **record,
        "experiment": unit.experiment,
        "curve": curve,
        "shared_from": first,
        "wall_s": 0.0,
        "fqi_s": 0.0,
        "physics_substeps": {},
    }


def _check_applies(spec: ExperimentSpec, name: str) -> None:
    """A built-in the spec does not list runs with its defaults: refuse it now if it cannot
    run on the spec's tasks (a grid planner on a pendulum), naming why."""
    check = contract(registry.build(name)).check
    if check is None:
        return
    try:
        check(sides.description_of(spec.source), sides.description_of(spec.target))
    except ValueError as error:
        raise MethodError(f"method {name!r} cannot run on {spec.name}: {error}") from None


class _Recorder:
    """Writes each finished unit (atomically) and collects failures; only the main process writes."""

    def __init__(self, run_dir: RunDirectory, done: set[Unit], bar: Any) -> None:
        self.run_dir, self.done, self.bar = run_dir, done, bar
        self.failures: list[str] = []
        self.failed = self.skipped = self.copied = 0

    def __call__(self, unit: Unit, result: dict) -> None:
        run_dir = self.run_dir
        path = run_dir.failure_path(unit.experiment, unit.seed, unit.name)
        if "error" in result:
            write_atomic(path, result["error"].encode())
            last = result["error"].strip().splitlines()[-1]
            self.failures.append(f"{unit}: {last} (see {path})")
            self.failed += 1
            self.bar.write(f"FAILED {unit}: {last}")
        else:
            run_dir.write_unit(unit.experiment, unit.seed, unit.name, result["record"], result.get("blob"))
            self.done.add(unit)
            path.unlink(missing_ok=True)  # an earlier run's traceback of this unit no longer applies
        self.bar.update(1)

    def copy(self, origin: Unit, unit: Unit) -> None:
        """Writes ``origin``'s finished record as ``unit``'s (see :func:`shared_record`)."""
        found = read_record(self.run_dir.record_path(origin.experiment, origin.seed, origin.name))
        self.run_dir.write_unit(unit.experiment, unit.seed, unit.name, shared_record(found, unit, origin))
        self.done.add(unit)
        self.copied += 1
        self.run_dir.failure_path(unit.experiment, unit.seed, unit.name).unlink(missing_ok=True)
        self.bar.update(1)

    def skip(self, unit: Unit, why: str) -> None:
        self.failures.append(f"{unit}: skipped, {why}")
        self.skipped += 1
        self.bar.update(1)


def run(
    specs: list[ExperimentSpec],
    preset: str,
    seeds: Iterable[int],
    out: str | Path,
    workers: int = 2,
    executor: str = "local",
    address: str | None = None,
    methods: Iterable[str] | dict[str, Any] | None = None,
    progress: bool = True,
    rehearse: bool = True,
) -> dict:
    """Runs (or resumes) every unit; writes and returns the summary.

    Raises :class:`RunFailed` (after every other unit finished and the summary was
    written) if any unit failed or was skipped; nothing finished is lost.

    ``methods``: None runs each spec's own ``[methods]``; a list of names runs
    those built-ins; a dict maps names to method objects implementing
    ``tatl_mj.transfer.method.TransferMethod`` (picklable, to run in worker processes), or to
    {experiment: such an object} for one with settings of its own per experiment.
    A spec with a ``[sweep]`` runs as one experiment per condition (``spec.conditions``).
    With ``rehearse``, each user method first learns on a tiny problem of each pair of tasks
    and its policy answers a few target states (``rehearsal``): :class:`MethodError` there.
    """
    dispatch = executors.dispatcher(executor, workers, address)
    specs = [condition for spec in specs for condition in conditions(spec)]  # a sweep: one per condition
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        raise ValueError(f"two specs share an experiment name: {names}")
    for spec in specs:
        spec.preset(preset)  # fail before any work on an unknown preset
    seeds = list(seeds)
    if not seeds or not specs or (methods is not None and not list(methods)):  # never touch a folder for nothing
        raise ValueError(f"nothing to run: {len(specs)} specs, {len(seeds)} seeds, methods {methods!r}")
    all_units, custom = _plan(specs, preset, seeds, methods)
    if rehearse:
        check_policies(specs, preset, custom, seeds[0])
    run_dir = RunDirectory(out)
    with lock.hold(run_dir.root):  # [robustness] one run per --out; raises lock.LockHeld
        run_dir.remove_temporaries()  # a crashed run's half-written files
        try:
            return _run_locked(
                specs, preset, seeds, run_dir, all_units, custom, progress, dispatch, workers=workers, executor=executor
            )
        finally:
            # A stop signal raises from its handler, which can land inside a write's cleanup.
            run_dir.remove_temporaries()


def _run_locked(
    specs: list[ExperimentSpec],
    preset: str,
    seeds: list[int],
    run_dir: RunDirectory,
    all_units: list[Unit],
    custom: dict[str, Any],
    progress: bool,
    dispatch: Callable[[executors.Work, list[executors.Job], executors.Then], None],
    **settings: Any,
) -> dict:
    """Runs every unit not done yet and writes the summary; ``settings`` (workers, executor) are
    recorded in it."""
    _check_manifest(run_dir, preset, specs)
    start = time.perf_counter()
    done = {u for u in all_units if run_dir.is_done(u.experiment, u.seed, u.name)}  # validated on read
    bar = tqdm(total=len(all_units), initial=len(done), desc="work units", unit="unit", disable=not progress)
    recorder = _Recorder(run_dir, done, bar)
    scheduler = Scheduler({s.name: s for s in specs}, preset, run_dir, all_units, custom, recorder)
    jobs = scheduler.first_jobs()
    if jobs:
        dispatch(work, jobs, scheduler.then)
    bar.close()

    method_names = list(dict.fromkeys(u.name for u in all_units if u.name != SOURCE_UNIT))
    inputs = dict(specs=[spec_to_dict(s) for s in specs], preset=preset, seeds=seeds, methods=method_names)
    extra = dict(wall_s=time.perf_counter() - start, failures=recorder.failures, **settings)
    ran = bool(jobs) or recorder.copied
    summary = None if ran else _unchanged_summary(run_dir, inputs, len(recorder.done) == len(all_units))
    if summary is None:
        summary = summary_mod.build(
            run_dir, **inputs, versions=_versions(), kernels=_kernel_counts(run_dir, all_units), **extra
        )
    else:
        summary.update(extra)
    write_json(run_dir.summary, summary)
    if recorder.failed or recorder.skipped:
        raise RunFailed(summary, recorder.failed, recorder.skipped, len(all_units), run_dir.root / "failures")
    return summary


def _unchanged_summary(run_dir: RunDirectory, inputs: dict, all_done: bool) -> dict | None:
    """The folder's summary.json when a rerun in which no unit ran would write the same one: the
    same specs, preset, seeds and methods, verdict rule and record schema, and every unit done.
    Its statistics (bootstrap intervals) are then not computed again."""
    try:
        old = read_json(run_dir.summary)
    except (FileNotFoundError, RecordError):
        return None
    inputs = json.loads(json.dumps(inputs))  # as summary.json holds them (tuples as lists)
    same = (
        isinstance(old, dict)
        and old.get("verdict_rule_version") == verdicts.VERDICT_RULE_VERSION
        and old.get("schema_version") == SCHEMA_VERSION
        and not old.get("failures")
        and [old.get("experiments", {}).get(s["name"], {}).get("spec") for s in inputs["specs"]] == inputs["specs"]
        and all(old.get(key) == value for key, value in inputs.items() if key != "specs")
        and len(old.get("experiments", {})) == len(inputs["specs"])
        and all_done  # validated when the run began
    )
    return old if same else None


class Scheduler:
    """Which units run when: sources first, each source's method units as soon as it is done,
    and the work experiments share done once (:func:`_shared`).

    A method without a source runs once for experiments that share its streams and target:
    the others get a copy of its record (at once, where the first is done already). A source
    unit of such experiments takes its source Q and target samples from the first of them
    (once that is done) and learns only its own mapping.
    """

    def __init__(
        self,
        by_name: dict[str, ExperimentSpec],
        preset: str,
        run_dir: RunDirectory,
        all_units: list[Unit],
        custom: dict[str, Any],
        recorder: _Recorder,
    ) -> None:
        self.by_name, self.preset, self.run_dir, self.custom, self.recorder = by_name, preset, run_dir, custom, recorder
        self.all_units, done = all_units, recorder.done
        self.copies: dict[Unit, list[Unit]] = {}
        self.later_sources: dict[Unit, list[Unit]] = {}
        for group in _shared(by_name, preset, all_units, custom):
            finished = [u for u in group if u in done]
            origin = finished[0] if finished else group[0]
            rest = [u for u in group if u not in done and u != origin]
            (self.later_sources if origin.name == SOURCE_UNIT else self.copies)[origin] = rest
        for origin, aliases in self.copies.items():
            if origin in done:
                for alias in aliases:
                    recorder.copy(origin, alias)
        followers = {alias for aliases in self.copies.values() for alias in aliases}
        # Each experiment and seed's method units wait for its source unit.
        self.waiting: dict[tuple[str, int], list[Unit]] = {}
        for unit in all_units:
            if unit.name != SOURCE_UNIT and unit not in done and unit not in followers:
                self.waiting.setdefault((unit.experiment, unit.seed), []).append(unit)

    def first_jobs(self) -> list[executors.Job]:
        """The sources not done (but those waiting for another's artefacts), and the methods of those done."""
        done = self.recorder.done
        sources = [u for u in self.all_units if u.name == SOURCE_UNIT]
        waiting_sources = {u for later in self.later_sources.values() for u in later}
        jobs = [self._job(u, None) for u in sources if u not in done | waiting_sources]
        for source in sources:
            if source in done:
                jobs += self._unlocked(source)
        return jobs

    def then(self, unit: Unit, result: dict) -> list[executors.Job]:
        """Records a finished unit (and its copies); returns the jobs it unlocked."""
        self.recorder(unit, result)
        for alias in self.copies.get(unit, []):
            if unit in self.recorder.done:
                self.recorder.copy(unit, alias)
            else:
                self.recorder.skip(alias, f"the unit it shares, {unit}, did not finish")
        return self._unlocked(unit) if unit.name == SOURCE_UNIT else []

    def _job(self, unit: Unit, blob: bytes | None) -> executors.Job:
        args = (self.by_name[unit.experiment], self.preset, unit, blob)
        transfer = self.custom.get(unit.name)
        if isinstance(transfer, dict):  # settings of its own per experiment
            transfer = transfer[unit.experiment]
        return unit, args if unit.name == SOURCE_UNIT else (*args, transfer)

    def _unlocked(self, source: Unit) -> list[executors.Job]:
        """The jobs waiting for ``source``: its method units (skipped if it failed), then the source
        units waiting for its artefacts (computed alone if it failed); its blob is read once, and
        only when a job needs it."""
        units = self.waiting.pop((source.experiment, source.seed), [])
        later = self.later_sources.get(source, [])
        if source not in self.recorder.done:
            for unit in units:
                self.recorder.skip(unit, "its source unit failed")
                for alias in self.copies.get(unit, []):
                    self.recorder.skip(alias, f"the unit it shares, {unit}, did not finish")
            return [self._job(u, None) for u in later]
        if not units and not later:
            return []
        blob = self.run_dir.read_blob(source.experiment, source.seed)
        return [self._job(u, blob) for u in units + later]
