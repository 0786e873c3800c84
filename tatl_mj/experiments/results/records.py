"""Finished work units on disk: one file each, written atomically, so nothing is lost.

A batch run that crashes or is killed leaves only whole records behind (a file
is written to a temporary name in the same folder, then renamed); the next run
of the same command skips every unit whose record exists and is valid.

Records are validated when read: a record that is not a JSON object with its
unit's keys, or a source cache (``source.pkl``) whose bytes do not match the
SHA-256 its record holds (a disk filled up, a copy cut short, a hand edit), is
moved aside to ``NAME.corrupt`` with a warning naming both paths, and the
unit is computed again.

Records are versioned (``schema_version``, :data:`SCHEMA_VERSION`): every unit
record and every summary this package writes carries the version it was written
in, and :func:`upgrade` is the one place that reads older ones, at read time
(:func:`read_record`), so nothing downstream carries a fallback for an older
field. A record from a newer schema is refused (:class:`SchemaError`).
"""

from __future__ import annotations

import hashlib
import io
import json
import logging
import os
import pickle
import uuid
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

SOURCE_UNIT = "source"
# Keys a finished record must have, by unit kind (see runner.work).
SOURCE_KEYS = ("random_return",)
METHOD_KEYS = ("curve", "final_return")
TEMPORARY = ".{name}.{tag}.tmp"  # where write_atomic writes before its rename

SCHEMA_VERSION = 3
"""The record schema this package writes. 1: records without ``schema_version`` (every
record before it was kept). 2: every unit record and summary names its schema; each
point of a method's curve counts ``rollout_transitions``, the real-target transitions
of policy rollouts charged at that budget (Algorithm 2's U_M rollouts), so that
``target_transitions - rollout_transitions`` is the paper's accounting; and every unit
record names its tasks' dynamics versions (``dynamics``: ``{"domain/task": N}``).
3: each point of a method's curve carries ``premises``, the theorem's premises measured
on its evaluation episodes (``tatl_mj.transfer.premises.PremiseMeasurements``' fields,
numbers or null; null for a method that is not TA-TL, and in every older record), and a
summary's method carries ``premises`` (per seed, per budget; ``results.summary``)."""
SHARED_DATA = "shared"
"""The ``data`` setting of a method that learns from the shared random-policy stream (counted by
``samples_used``)."""
RENAMED_DATA = {"stream": SHARED_DATA}
"""Older records' words for a ``data`` protocol, by today's: the grid planner said ``"stream"`` for the
shared stream until one word named it (read as ``"shared"`` by :func:`upgrade`)."""
UNKNOWN_KERNELS = "unknown"
"""The ``kernels`` of a schema-1 record older than that field."""


MOVED_MODULES = {
    "tatl_mj.experiments.pipeline": "tatl_mj.experiments.run.pipeline",
    "tatl_mj.experiments.mappings": "tatl_mj.transfer.mappings",
}
"""Modules whose classes a source cache (``source.pkl``) written before a move names: old path -> new."""
MOVED_NAMES: dict[tuple[str, str], str] = {
    ("tatl_mj.experiments.run.pipeline", "SourceArtifacts"): "tatl_mj.experiments.run.source_unit",
    ("tatl_mj.experiments.run.pipeline", "QueriedMapping"): "tatl_mj.experiments.run.problems",
    ("tatl_mj.experiments.run.pipeline", "_source_region"): "tatl_mj.experiments.run.problems",  # QueriedMapping's
    ("tatl_mj.transfer.alignment", "Mapping"): "tatl_mj.transfer.intertask_mapping",
    ("tatl_mj.transfer.alignment", "IdentityMapping"): "tatl_mj.transfer.intertask_mapping",
    ("tatl_mj.transfer.alignment", "AffineMapping"): "tatl_mj.transfer.intertask_mapping",
    ("tatl_mj.transfer.alignment", "LinearAlignment"): "tatl_mj.transfer.manifold_alignment",
    ("tatl_mj.transfer.alignment", "TransitionAlignment"): "tatl_mj.transfer.transition_alignment",
    ("tatl_mj.transfer.alignment", "_IncrementModel"): "tatl_mj.transfer.transition_alignment",
}
"""Single classes or functions that left a module split in parts: (old module, name) -> new module
(the old module as ``MOVED_MODULES`` leaves it: it is applied first)."""


class _MovedUnpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str) -> Any:
        module = MOVED_MODULES.get(module, module)
        return super().find_class(MOVED_NAMES.get((module, name), module), name)


def load_blob(blob: bytes) -> Any:
    """A source cache's artefacts, read from a run folder written before or after a module moved
    (a resumed run must not lose its finished sources to a rename)."""
    return _MovedUnpickler(io.BytesIO(blob)).load()


class RecordError(ValueError):
    """A file under a run folder is unreadable or malformed; the message names it."""


class SchemaError(RecordError):
    """A record written in a newer schema than this package reads; the message names the file."""


def write_atomic(path: Path, data: bytes) -> None:
    """Writes ``data`` to ``path`` so that readers see the old file or the whole new one."""
    path.parent.mkdir(parents=True, exist_ok=True)
    # os.open with 0o666 honours the user's umask (mkstemp would always give 0600).
    tmp = str(path.parent / TEMPORARY.format(name=path.name, tag=uuid.uuid4().hex))
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_json(path: Path, record: Any) -> None:
    write_atomic(path, (json.dumps(record, indent=1, sort_keys=True) + "\n").encode())


def read_json(path: Path) -> Any:
    """Parses a JSON file; anything but a missing file raises :class:`RecordError` naming it."""
    path = Path(path)
    try:
        return json.loads(path.read_bytes().decode("utf-8"))
    except FileNotFoundError:
        raise
    except (OSError, UnicodeDecodeError, ValueError) as error:
        raise RecordError(f"{path}: unreadable or not valid JSON ({type(error).__name__}: {error})") from None


def read_record(path: Path) -> dict:
    """A unit's record or a summary from ``path``, in the current schema (:func:`upgrade`)."""
    return upgrade(read_json(path), path)


def upgrade(record: Any, where: str | Path = "<record>") -> dict:
    """``record`` (a unit's record or a summary, read from ``where``) in schema :data:`SCHEMA_VERSION`.

    Raises :class:`SchemaError` for a newer schema and :class:`RecordError` for a
    record that is not one or lacks what no upgrade can derive; each names ``where``.
    """
    if not isinstance(record, dict):
        raise RecordError(f"{where}: a JSON object expected, got {type(record).__name__}")
    version = record.get("schema_version", 1)
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise RecordError(f"{where}: schema_version must be a whole number >= 1, got {version!r}")
    if version > SCHEMA_VERSION:
        raise SchemaError(
            f"{where}: record schema {version} is newer than this tatl-mj reads (schemas 1 to "
            f"{SCHEMA_VERSION}); install a newer tatl-mj to read it"
        )
    if version == 1:
        try:
            record = _summary_v2(record) if "experiments" in record else _unit_v2(record)
        except (KeyError, TypeError) as error:
            raise RecordError(f"{where}: a schema-1 record without {error}, which no upgrade can derive") from None
    if record.get("schema_version") == 2:
        record = _v3(record)
    return _data_words(record)


def _v3(record: dict) -> dict:
    """A schema-2 record in schema 3: nothing was measured of the premises (None)."""
    if "experiments" in record:
        experiments = {}
        for name, experiment in record["experiments"].items():
            methods = experiment.get("methods") or {}
            experiments[name] = {**experiment, "methods": {k: {"premises": None, **m} for k, m in methods.items()}}
        return {**record, "schema_version": 3, "experiments": experiments}
    if isinstance(record.get("curve"), list):
        record = {**record, "curve": [{"premises": None, **p} for p in record["curve"]]}
    return {**record, "schema_version": 3}


def _data_words(record: dict) -> dict:
    """``record`` with today's word for each ``data`` protocol (:data:`RENAMED_DATA`)."""
    if "experiments" in record:
        renamed = {}
        for name, experiment in record["experiments"].items():
            methods = experiment.get("methods") or {}
            if any(m.get("data") in RENAMED_DATA for m in methods.values()):
                methods = {k: _data_word(m) for k, m in methods.items()}
                experiment = {**experiment, "methods": methods}
            renamed[name] = experiment
        return {**record, "experiments": renamed}
    return _data_word(record)


def _data_word(entry: dict) -> dict:
    data = entry.get("data")
    return {**entry, "data": RENAMED_DATA[data]} if data in RENAMED_DATA else entry


def _unit_v2(record: dict) -> dict:
    """A schema-1 unit record (source or method) in schema 2."""
    # Schema 1 named neither kernels (at first) nor dynamics versions: {} names none.
    out = {**record, "schema_version": 2, "kernels": record.get("kernels", UNKNOWN_KERNELS), "dynamics": {}}
    if "curve" not in record:
        return out  # a source unit's
    data = record.get("data", "shared")  # the only protocol before records named theirs

    def point(p: dict) -> dict:
        if "steps" not in p:  # per-episode lengths (survival) cannot be made up
            raise KeyError("steps")
        counted = p.get("target_transitions", p["samples"])  # before counting: the budget
        rollouts = counted - p["samples_used"] if data in (SHARED_DATA, *RENAMED_DATA) else 0
        return {**p, "target_transitions": counted, "rollout_transitions": rollouts}

    return {**out, "data": data, "curve": [point(p) for p in record["curve"]]}


def _summary_v2(summary: dict) -> dict:
    """A schema-1 summary in schema 2: what its readers (the tables, the figures) take."""
    experiments = {}
    for name, experiment in summary["experiments"].items():
        experiment = dict(experiment)
        methods = experiment["methods"]
        if "random_returns" not in experiment and experiment.get("random_return") is not None:
            # Before per-seed random returns: one value for every seed.
            seeds = sorted({s for m in methods.values() for s in m.get("seeds", [])})
            experiment["source_seeds"] = seeds
            experiment["random_returns"] = [float(experiment["random_return"])] * len(seeds)
        experiment["methods"] = {
            m: {
                **data,
                "data": data.get("data", "shared"),
                "curve": {
                    **data["curve"],
                    "target_transitions": data["curve"].get(
                        "target_transitions", [list(data["curve"]["samples"])] * len(data["seeds"])
                    ),
                    # Before rollouts were counted apart: none (the paper's accounting is the counted one).
                    "rollout_transitions": data["curve"].get(
                        "rollout_transitions", [[0] * len(data["curve"]["samples"])] * len(data["seeds"])
                    ),
                },
            }
            for m, data in methods.items()
        }
        experiments[name] = experiment
    return {
        **summary,
        "kernels": summary.get("kernels") or {},
        "verdict_rule_version": summary.get("verdict_rule_version", 1),  # before the field: rule 1
        "threshold_fraction": summary.get("threshold_fraction", 0.95),
        "reference_threshold": summary.get("reference_threshold", 0.9),
        "schema_version": 2,
        "experiments": experiments,
    }


def quarantine(path: Path, reason: str) -> Path:
    """Moves a corrupt file aside to ``NAME.corrupt`` (``NAME.corrupt.N`` if taken); returns the new path."""
    path = Path(path)
    target, n = path.with_name(path.name + ".corrupt"), 1
    while target.exists():
        target, n = path.with_name(f"{path.name}.corrupt.{n}"), n + 1
    os.replace(path, target)
    log.warning("tatl: %s is corrupt (%s); moved aside to %s, it will be recomputed", path, reason, target)
    return target


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _record_problem(record: Any, unit: str) -> str | None:
    if not isinstance(record, dict):
        return f"a JSON object expected, got {type(record).__name__}"
    missing = [k for k in (SOURCE_KEYS if unit == SOURCE_UNIT else METHOD_KEYS) if k not in record]
    return f"missing keys {missing}" if missing else None


def _blob_problem(blob: bytes, expected: Any) -> str | None:
    if isinstance(expected, str):
        return None if sha256(blob) == expected else "its SHA-256 does not match its record's"
    # A record written before checksums: every pickle ends with the STOP opcode.
    return None if blob.endswith(pickle.STOP) else "truncated pickle (no STOP opcode at its end)"


class RunDirectory:
    """The layout of ``tatl run --out DIR``.

    DIR/run.json                          the preset and specs this folder belongs to
    DIR/records/EXP/seedN/source.pkl      phase I-II artefacts (source Q, mapping, data)
    DIR/records/EXP/seedN/source.json     their metadata and timings
    DIR/records/EXP/seedN/METHOD.json     one method's learning curve for one seed
    DIR/failures/EXP__seedN__UNIT.txt     the traceback of a unit that failed
    DIR/summary.json                      everything above, aggregated
    """

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)

    def unit_dir(self, experiment: str, seed: int) -> Path:
        return self.root / "records" / experiment / f"seed{seed}"

    def record_path(self, experiment: str, seed: int, unit: str) -> Path:
        return self.unit_dir(experiment, seed) / f"{unit}.json"

    def blob_path(self, experiment: str, seed: int) -> Path:
        return self.unit_dir(experiment, seed) / "source.pkl"

    def failure_path(self, experiment: str, seed: int, unit: str) -> Path:
        return self.root / "failures" / f"{experiment}__seed{seed}__{unit}.txt"

    def is_done(self, experiment: str, seed: int, unit: str) -> bool:
        """True when the unit's record (and, for a source unit, its cache) is present and valid.

        A corrupt one is moved aside (see :func:`quarantine`), so the unit runs again.
        """
        path = self.record_path(experiment, seed, unit)
        if not path.exists():
            return False
        try:
            record = read_record(path)  # a newer schema's raises SchemaError: refused, not moved aside
            problem = _record_problem(record, unit)
        except SchemaError:
            raise
        except RecordError as error:
            record, problem = None, str(error).split(": ", 1)[-1]
        if problem:
            quarantine(path, problem)
            return False
        if unit != SOURCE_UNIT:
            return True
        blob_path = self.blob_path(experiment, seed)
        try:
            problem = _blob_problem(blob_path.read_bytes(), record.get("blob_sha256"))
        except FileNotFoundError:
            problem = f"its cache {blob_path} is missing"
        if problem:
            if blob_path.exists():
                quarantine(blob_path, problem)
            quarantine(path, f"its cache is unusable: {problem}")
            return False
        return True

    def write_unit(self, experiment: str, seed: int, unit: str, record: dict, blob: bytes | None = None) -> None:
        """Writes a finished unit: its cache first (if any), then its record with the cache's
        SHA-256, in the current schema."""
        record = {**record, "schema_version": SCHEMA_VERSION}
        if blob is not None:
            write_atomic(self.blob_path(experiment, seed), blob)
            record = {**record, "blob_sha256": sha256(blob)}
        write_json(self.record_path(experiment, seed, unit), record)

    def read_blob(self, experiment: str, seed: int) -> bytes:
        """The source cache of (experiment, seed); call :meth:`is_done` for the source unit first."""
        return self.blob_path(experiment, seed).read_bytes()

    def remove_temporaries(self) -> int:
        """Removes the temporary files of writes cut short (by a stop signal, or a crash);
        call only while holding the folder's lock. Returns how many it removed."""
        removed = 0
        for path in self.root.rglob(TEMPORARY.format(name="*", tag="*")):
            path.unlink(missing_ok=True)
            removed += 1
        return removed

    @property
    def manifest(self) -> Path:
        return self.root / "run.json"

    @property
    def summary(self) -> Path:
        return self.root / "summary.json"
