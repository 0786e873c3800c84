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
(:func:`pipeline.one_thread`), as a one-CPU Ray task does, so its record depends
neither on the executor nor on the machine's core count.
"""

from __future__ import annotations

import collections
import dataclasses
import json
import os
import pickle
import platform
import sys
import time
import traceback
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from importlib import metadata
from pathlib import Path
from typing import Any, Callable, Iterable

from tqdm import tqdm

from tatl_mj import sampling
from tatl_mj.experiments import lock, pipeline, reaper
from tatl_mj.experiments import summary as summary_mod
from tatl_mj.experiments import workers as workers_mod
from tatl_mj.experiments.kernels import kernels
from tatl_mj.experiments.records import SOURCE_UNIT, RunDirectory, read_json, read_record, write_atomic, write_json
from tatl_mj.experiments.spec import ExperimentSpec, conditions, dynamics_versions, spec_to_dict
from tatl_mj.transfer import fit_time, registry
from tatl_mj.transfer.method import contract

EXECUTORS = ("local", "ray")


class MethodError(ValueError):
    """A method asked for that a spec cannot run (raised before any work starts)."""


class ExecutorError(RuntimeError):
    """The executor cannot start: e.g. no Ray cluster answers at ``address`` (raised before any work)."""


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
        with pipeline.one_thread():  # workers run in parallel; records must not see the core count
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
        shared = pickle.loads(source_blob) if source_blob is not None else None
        artifacts = pipeline.learn_source(spec, preset, unit.seed, shared)
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
        artifacts = pickle.loads(source_blob)
        blob = None
        record = pipeline.run_method(spec, preset, unit.seed, unit.name, artifacts, transfer=transfer)
    record["kernels"] = kernels()  # what it depends on besides its settings and seed
    record["dynamics"] = dynamics_versions(spec)  # and the versions of its tasks' dynamics
    record["wall_s"] = time.perf_counter() - start
    record["fqi_s"] = fit_time.fqi_seconds() - fits  # a cost, like wall_s: its part in FQI's fits
    # A cost, like wall_s: the MuJoCo substeps this unit took, by task.
    record["physics_substeps"] = {
        key: n - substeps.get(key, 0) for key, n in sampling.physics_substeps().items() if n > substeps.get(key, 0)
    }
    return {"record": record, "blob": blob}


# --- executors ------------------------------------------------------------------

Job = tuple[Unit, tuple]


Then = Callable[[Unit, dict], list[Job]]
"""What a dispatcher calls with each finished unit's result: it records the result
and returns the jobs that unit has unlocked (a source's methods), to run next."""


def _local(jobs: list[Job], workers: int, then: Then) -> None:
    if workers <= 1:
        queue = collections.deque(jobs)
        while queue:
            unit, args = queue.popleft()
            queue.extend(then(unit, work(*args)))
        return
    import multiprocessing

    # spawn: MuJoCo/GL state must not be forked into workers.
    # [robustness] workers die with this process, however it dies.
    # One pool for sources and methods: a method starts as soon as its source is done.
    with ProcessPoolExecutor(
        max_workers=workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=workers_mod.die_with_parent,
        initargs=(os.getpid(),),
    ) as pool:
        futures = {pool.submit(work, *args): unit for unit, args in jobs}
        while futures:
            done, _ = wait(futures, return_when=FIRST_COMPLETED)
            for future in done:
                unit = futures.pop(future)
                try:
                    result = future.result()
                except Exception:  # noqa: BLE001 - e.g. a worker killed by the OS
                    result = {"error": traceback.format_exc()}
                for next_unit, args in then(unit, result):
                    futures[pool.submit(work, *args)] = next_unit


CONNECT_TIMEOUT_S = 10.0


def check_address(address: str) -> None:
    """Raises ExecutorError unless something accepts connections at a Ray ``address``.

    ``ray.init`` retries an address where nothing listens for minutes (measured with
    Ray 2.60); one TCP connection here, to the address given and nowhere else, says
    at once. ``auto`` and ``local`` are left to Ray.
    """
    import socket

    if address in ("auto", "local"):
        return
    where = address.split("://", 1)[-1]  # ray://host:port (Ray Client) or host:port
    host, _, port = where.rpartition(":")
    if not host or not port.isdigit():
        raise ExecutorError(
            f"--address {address!r}: expected host:port (e.g. 127.0.0.1:6379), 'auto' or ray://host:port"
        )
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as error:
        raise ExecutorError(
            f"no Ray cluster answers at --address {address} ({error.strerror or error}); "
            "start one there (ray start --head --port PORT) or give its address"
        ) from None


def _ray(jobs: list[Job], workers: int, address: str | None, then: Then) -> None:
    try:
        import ray
    except ImportError:
        raise SystemExit(
            "--executor ray needs Ray: pip install 'tatl-mj[ray]' (or pip install 'ray>=2.9,<3')"
        ) from None
    started = not ray.is_initialized()
    # [robustness] a local instance's agents would outlive a killed run by 20-30 s.
    watcher = reaper.start() if started and not address else None
    if started:
        kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False}
        if address:
            kwargs["address"] = address
        else:
            kwargs["num_cpus"] = max(workers, 1)
        try:
            ray.init(**kwargs)
        except Exception as error:  # noqa: BLE001 - Ray raises several kinds (ConnectionError, RuntimeError)
            ray.shutdown()
            if watcher is not None:
                watcher.terminate()
                watcher.wait()
            first = (str(error).strip().splitlines() or [type(error).__name__])[0]
            where = f"at {address}" if address else "(a local instance)"
            raise ExecutorError(f"cannot start Ray {where}: {first}") from None
    try:
        remote = ray.remote(num_cpus=1)(work)
        refs = {remote.remote(*args): unit for unit, args in jobs}
        while refs:
            done, _ = ray.wait(list(refs), num_returns=1)
            for ref in done:
                unit = refs.pop(ref)
                try:
                    result = ray.get(ref)
                except Exception:  # noqa: BLE001 - a lost node or worker
                    result = {"error": traceback.format_exc()}
                for next_unit, args in then(unit, result):
                    refs[remote.remote(*args)] = next_unit
    finally:
        if started:
            ray.shutdown()
        if watcher is not None:
            watcher.terminate()
            watcher.wait()


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
            raise SystemExit(
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
    custom = {k: registry.resolve(v, label=k) for k, v in given if v is not None}
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


# What a method unit's record may depend on besides its method and seed: everything in
# its spec but the experiment's names, its mapping and its other methods.
_NOT_SHARED = ("name", "title", "paper_claim", "paper", "best_baseline", "path", "mapping", "methods", "streams")


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
    transfer = pipeline.methods_from_spec(spec, spec.preset(preset), [unit.name])[unit.name]
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
    curve = [{**point, "learn_s": 0.0, "evaluate_s": 0.0} for point in record["curve"]]
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
        check(pipeline.description_of(spec.source), pipeline.description_of(spec.target))
    except ValueError as error:
        raise MethodError(f"method {name!r} cannot run on {spec.name}: {error}") from None


def _dispatcher(executor: str, workers: int, address: str | None) -> Callable[[list[Job], Then], None]:
    if executor not in EXECUTORS:
        raise ValueError(f"unknown executor {executor!r}; valid executors: {list(EXECUTORS)}")
    if executor == "ray" and address:
        check_address(address)  # before the run touches its folder
    if executor == "ray":
        return lambda jobs, then: _ray(jobs, workers, address, then)
    return lambda jobs, then: _local(jobs, workers, then)


class _Recorder:
    """Writes each finished unit (atomically) and collects failures; only the main process writes."""

    def __init__(self, run_dir: RunDirectory, done: set[Unit], bar: Any) -> None:
        self.run_dir, self.done, self.bar = run_dir, done, bar
        self.failures: list[str] = []
        self.failed = self.skipped = 0

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
) -> dict:
    """Runs (or resumes) every unit; writes and returns the summary.

    Raises :class:`RunFailed` (after every other unit finished and the summary was
    written) if any unit failed or was skipped; nothing finished is lost.

    ``methods``: None runs each spec's own ``[methods]``; a list of names runs
    those built-ins; a dict maps names to method objects implementing
    ``tatl_mj.transfer.method.TransferMethod`` (picklable, to run in worker processes).
    A spec with a ``[sweep]`` runs as one experiment per condition (``spec.conditions``).
    """
    dispatch = _dispatcher(executor, workers, address)
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
    run_dir = RunDirectory(out)
    with lock.hold(run_dir.root):  # [robustness] one run per --out; raises lock.LockHeld
        run_dir.remove_temporaries()  # a crashed run's half-written files
        try:
            return _run_locked(specs, preset, seeds, run_dir, workers, executor, all_units, custom, progress, dispatch)
        finally:
            # A stop signal raises from its handler, which can land inside a write's cleanup.
            run_dir.remove_temporaries()


def _run_locked(
    specs: list[ExperimentSpec],
    preset: str,
    seeds: list[int],
    run_dir: RunDirectory,
    workers: int,
    executor: str,
    all_units: list[Unit],
    custom: dict[str, Any],
    progress: bool,
    dispatch: Callable[[list[Job], Then], None],
) -> dict:
    _check_manifest(run_dir, preset, specs)
    start = time.perf_counter()
    by_name = {s.name: s for s in specs}
    done = {u for u in all_units if run_dir.is_done(u.experiment, u.seed, u.name)}  # validated on read
    bar = tqdm(total=len(all_units), initial=len(done), desc="work units", unit="unit", disable=not progress)
    record = _Recorder(run_dir, done, bar)

    # A method without a source runs once for experiments that share its streams and
    # target: the others get its record (now, where one of them is done already).
    # A source unit of such experiments takes its source Q and target samples from the
    # first of them (once that is done) and learns only its own mapping.
    copies: dict[Unit, list[Unit]] = {}
    later_sources: dict[Unit, list[Unit]] = {}
    for group in _shared(by_name, preset, all_units, custom):
        finished = [u for u in group if u in done]
        origin = finished[0] if finished else group[0]
        rest = [u for u in group if u not in done and u != origin]
        (later_sources if origin.name == SOURCE_UNIT else copies)[origin] = rest
    for origin, aliases in copies.items():
        if origin in done:
            for alias in aliases:
                record.copy(origin, alias)
    followers = {alias for aliases in copies.values() for alias in aliases}

    # Each experiment and seed's method units wait for its source unit, and start when it is done.
    waiting: dict[tuple[str, int], list[Unit]] = {}
    for unit in all_units:
        if unit.name != SOURCE_UNIT and unit not in done and unit not in followers:
            waiting.setdefault((unit.experiment, unit.seed), []).append(unit)

    def methods_of(source: Unit) -> list[Job]:
        units = waiting.pop((source.experiment, source.seed), [])
        if source not in done:
            for unit in units:
                record.skip(unit, "its source unit failed")
                for alias in copies.get(unit, []):
                    record.skip(alias, f"the unit it shares, {unit}, did not finish")
            return []
        blob = run_dir.read_blob(source.experiment, source.seed) if units else None
        return [(u, (by_name[u.experiment], preset, u, blob, custom.get(u.name))) for u in units]

    def sources_after(origin: Unit) -> list[Job]:
        """The source units waiting for ``origin``'s artefacts (computed alone if it failed)."""
        blob = run_dir.read_blob(origin.experiment, origin.seed) if origin in done else None
        return [(u, (by_name[u.experiment], preset, u, blob)) for u in later_sources.get(origin, [])]

    def then(unit: Unit, result: dict) -> list[Job]:
        record(unit, result)
        for alias in copies.get(unit, []):
            if unit in done:
                record.copy(unit, alias)
            else:
                record.skip(alias, f"the unit it shares, {unit}, did not finish")
        return methods_of(unit) + sources_after(unit) if unit.name == SOURCE_UNIT else []

    sources = [u for u in all_units if u.name == SOURCE_UNIT]
    waiting_sources = {u for later in later_sources.values() for u in later}
    jobs = [(u, (by_name[u.experiment], preset, u, None)) for u in sources if u not in done | waiting_sources]
    for source in sources:
        if source in done:
            jobs += methods_of(source) + sources_after(source)
    dispatch(jobs, then)
    bar.close()

    method_names = list(dict.fromkeys(u.name for u in all_units if u.name != SOURCE_UNIT))
    summary = summary_mod.build(
        run_dir,
        specs=[spec_to_dict(s) for s in specs],
        preset=preset,
        seeds=seeds,
        methods=method_names,
        versions=_versions(),
        kernels=_kernel_counts(run_dir, all_units),
        wall_s=time.perf_counter() - start,
        workers=workers,
        executor=executor,
        failures=record.failures,
    )
    write_json(run_dir.summary, summary)
    if record.failed or record.skipped:
        raise RunFailed(summary, record.failed, record.skipped, len(all_units), run_dir.root / "failures")
    return summary


def timings(run_dir: str | Path) -> dict[str, dict[str, float]]:
    """Summed seconds per experiment and phase from a run's records (all seeds): source
    learning, target sampling, mapping, the random reference, and each method's learning
    and evaluation. What ``tatl run`` prints at its end."""
    out: dict[str, dict[str, float]] = {}
    root = RunDirectory(run_dir).root / "records"
    for path in sorted(root.glob("*/seed*/*.json")):
        experiment, unit = path.parent.parent.name, path.stem
        try:
            record = read_json(path)
        except ValueError:
            continue  # a corrupt record is named and recomputed by the next run
        phases = out.setdefault(experiment, {})
        if unit == SOURCE_UNIT:
            for key, value in record.get("timings", {}).items():
                phases[key.removesuffix("_s")] = phases.get(key.removesuffix("_s"), 0.0) + float(value)
            continue
        for part in ("learn", "evaluate"):
            key = f"{unit} {part}"
            phases[key] = phases.get(key, 0.0) + sum(float(p.get(f"{part}_s", 0.0)) for p in record.get("curve", []))
    return out


def physics_report(
    run_dir: str | Path, seconds: float = 0.3, repeats: int = 3, previous: dict[str, Any] | None = None
) -> dict[str, Any]:
    """A run's work against its physics: the summed unit wall times (``work_s``), and the
    MuJoCo substeps its units took priced at raw ``mujoco.rollout`` speed on one thread
    (``physics_s``: per task, the fastest of ``repeats`` timings of ``seconds`` each, taken
    now), and their ratio. Records without a substep count (older ones) are left out of both.

    ``fqi_s`` is the part of the work spent in FQI's fits, and ``floor_s`` the physics and
    those fits together: all but the rest of the work, which is what code that keeps
    the fits can save (both None when some counted records do not time their fits).

    ``previous``: an earlier report of this folder (its physics.json), returned as it is
    when the records hold the same work (no unit ran since), so a finished run's rerun
    does not time the physics again."""
    from tatl_mj import bench

    counted = _physics_counts(run_dir)
    if previous is not None and {k: previous.get(k) for k in counted} == counted:
        return previous
    by_task = {}
    for key, n in sorted(counted["substeps"].items()):
        domain, task = key.split("/", 1)
        # The fastest of a few: one short timing moved the ratio by a fifth on a drifting machine.
        tries = [bench.time_rollout(domain, task, seconds, threads=1) for _ in range(repeats)]
        timed = max(tries, key=lambda t: t["steps_per_s"])
        rate = timed["steps_per_s"] * timed["substeps"]
        by_task[key] = {"substeps": n, "raw_substeps_per_s": rate, "raw_s": n / rate}
    physics_s = sum(v["raw_s"] for v in by_task.values())
    work_s, fqi_s = counted["work_s"], counted["fqi_s"]
    return {
        **counted,
        "physics_s": physics_s,
        "ratio": work_s / physics_s if physics_s else None,
        "floor_s": None if fqi_s is None else physics_s + fqi_s,
        "by_task": by_task,
    }


def _physics_counts(run_dir: str | Path) -> dict[str, Any]:
    """What :func:`physics_report` sums from the records: work, FQI's part, substeps by task,
    and how many records have no substep count."""
    substeps: dict[str, int] = {}
    work_s, fqi_s, uncounted, untimed = 0.0, 0.0, 0, 0
    for path in sorted((RunDirectory(run_dir).root / "records").glob("*/seed*/*.json")):
        try:
            record = read_json(path)
        except ValueError:
            continue
        if "physics_substeps" not in record:
            uncounted += 1  # written before substeps were counted: neither side counts it
            continue
        work_s += float(record.get("wall_s", 0.0))
        if "fqi_s" in record:
            fqi_s += float(record["fqi_s"])
        else:
            untimed += 1
        for key, n in record["physics_substeps"].items():
            substeps[key] = substeps.get(key, 0) + int(n)
    return {
        "work_s": work_s,
        "fqi_s": None if untimed else fqi_s,
        "substeps": dict(sorted(substeps.items())),
        "records_without_counts": uncounted,
    }


def format_physics(report: dict[str, Any]) -> str:
    """Work, physics at raw speed and their ratio; then, where every record times them,
    FQI's fits and the floor they make with the physics."""
    if not report["physics_s"]:
        return f"work: {report['work_s']:.1f} s; no MuJoCo substeps recorded (tasks without physics, or older records)"
    substeps = sum(v["substeps"] for v in report["by_task"].values())
    left_out = report.get("records_without_counts", 0)
    note = f" ({left_out} older records without counts left out of both)" if left_out else ""
    line = (
        f"work: {report['work_s']:.1f} s over the records; physics: {substeps:,} MuJoCo substeps = "
        f"{report['physics_s']:.1f} s at raw mujoco.rollout speed (1 thread); "
        # Two decimals: the target is 3x, and 3.04 must not print as 3.0.
        f"work / physics = {report['ratio']:.2f}x{note}"
    )
    if report.get("floor_s") is None:
        return line
    rest = report["work_s"] - report["floor_s"]
    # Raw speed is timed after the run: on a machine that slowed since, it prices the physics above its cost.
    why = " (below 0: MuJoCo ran slower when timed than during the run)" if rest < 0 else ""
    return (
        f"{line}\nFQI's fits: {report['fqi_s']:.1f} s of the work; physics at raw speed + FQI's fits = "
        f"{report['floor_s']:.1f} s; everything else {rest:.1f} s{why}"
    )


def format_timings(table: dict[str, dict[str, float]]) -> str:
    """The breakdown as text: per experiment, its phases from the slowest, with their share."""
    lines = []
    for experiment, phases in table.items():
        total = sum(phases.values()) or 1.0
        lines.append(f"{experiment}: {total:.1f} s of work")
        for phase, seconds in sorted(phases.items(), key=lambda kv: -kv[1]):
            if seconds >= 0.05 * total:
                lines.append(f"  {phase:<32} {seconds:8.1f} s  {100 * seconds / total:4.0f}%")
    return "\n".join(lines)
