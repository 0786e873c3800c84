"""Finished work units on disk: one file each, written atomically, so nothing is lost.

A batch run that crashes or is killed leaves only whole records behind (a file
is written to a temporary name in the same folder, then renamed); the next run
of the same command skips every unit whose record exists and is valid.

Records are validated when read: a record that is not a JSON object with its
unit's keys, or a source cache (``source.pkl``) whose bytes do not match the
SHA-256 its record holds (a disk filled up, a copy cut short, a hand edit), is
moved aside to ``NAME.corrupt`` with a warning naming both paths, and the
unit is computed again.
"""

from __future__ import annotations

import hashlib
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


class RecordError(ValueError):
    """A file under a run folder is unreadable or malformed; the message names it."""


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
            record = read_json(path)
            problem = _record_problem(record, unit)
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
        """Writes a finished unit: its cache first (if any), then its record with the cache's SHA-256."""
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
