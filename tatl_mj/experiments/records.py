"""Finished work units on disk: one file each, written atomically, so nothing is lost.

A batch run that crashes or is killed leaves only whole records behind (a file
is written to a temporary name in the same folder, then renamed); the next run
of the same command skips every unit whose record exists.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any


def write_atomic(path: Path, data: bytes) -> None:
    """Writes ``data`` to ``path`` so that readers see the old file or the whole new one."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
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
    return json.loads(path.read_text())


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

    @property
    def manifest(self) -> Path:
        return self.root / "run.json"

    @property
    def summary(self) -> Path:
        return self.root / "summary.json"
