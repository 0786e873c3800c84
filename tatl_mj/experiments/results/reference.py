"""Reference sets: a finished run's records, published compactly with a manifest.

A set is a folder, ``reference/NAME/`` at the top of the repository (installed
with the package, as ``tatl_mj/reference`` links to it, like the MJCF assets):

    manifest.json       what made the records and what they depend on (:class:`Manifest`)
    specs.json.xz       each experiment's resolved spec, as summary.json keeps it
    records.jsonl.xz    one line per unit record: {"experiment", "seed", "unit", "record"}

The records are the run's JSON records as they are, in the current schema, without
the pickled sources (a reader that needs a source, ``tatl compare``, computes it
again). :func:`build` makes a set from a finished run folder; :func:`unpack` gives
back a run folder that ``tatl plot`` reads, its summary built by this package's
rule. xz (the standard library's ``lzma``): the records are mostly long float reprs,
which it packs about a fifth smaller than gzip does.
"""

from __future__ import annotations

import collections
import dataclasses
import hashlib
import json
import lzma
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from tatl_mj.experiments.results import summary as summary_mod
from tatl_mj.experiments.results import summary_data
from tatl_mj.experiments.results.records import (
    SCHEMA_VERSION,
    SOURCE_UNIT,
    RecordError,
    RunDirectory,
    read_json,
    read_record,
    upgrade,
    write_atomic,
    write_json,
)
from tatl_mj.experiments.spec import content_hash

REFERENCE_ROOT = Path(__file__).resolve().parents[2] / "reference"
"""Where the shipped sets live (``tatl_mj/reference``, a link to the repository's ``reference/``)."""
MANIFEST = "manifest.json"
SPECS = "specs.json.xz"
RECORDS = "records.jsonl.xz"


class ReferenceError(ValueError):
    """A reference set that cannot be built, found or read; one line naming what and how to fix it."""


@dataclasses.dataclass(frozen=True)
class Manifest:
    """What a set's records are and what they depend on.

    ``experiments``: per experiment, its spec's ``content_hash`` (for the set's preset),
    the ``dynamics`` version of each of its tasks and the ``methods`` whose records it
    holds. ``kernels``: how many records each set of arithmetic kernels computed.
    ``fragile_verdicts``: verdicts known to move with the kernels, each ``{"experiment",
    "method", "versus", "why"}`` (filled in by hand from the cross-machine checks).
    ``files``: each data file's SHA-256, checked when the set is read.
    """

    name: str
    package_version: str
    schema_version: int
    verdict_rule_version: int
    preset: str
    seeds: tuple[int, ...]
    command: str
    experiments: dict[str, dict[str, Any]]
    kernels: dict[str, int]
    versions: dict[str, Any]
    records: int
    files: dict[str, str]
    fragile_verdicts: tuple[dict[str, str], ...] = ()

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, data: Any, where: Path) -> Manifest:
        fields = {f.name for f in dataclasses.fields(cls)}
        required = {f.name for f in dataclasses.fields(cls) if f.default is dataclasses.MISSING}
        if not isinstance(data, dict) or not required <= set(data) or not set(data) <= fields:
            keys = sorted(data) if isinstance(data, dict) else type(data).__name__
            raise ReferenceError(f"{where}: not a reference manifest (keys {keys}; expected {sorted(fields)})")
        data = {**data, "seeds": tuple(data["seeds"]), "fragile_verdicts": tuple(data.get("fragile_verdicts", ()))}
        return cls(**data)

    def methods(self, experiment: str) -> list[str]:
        return list(self.experiments[experiment]["methods"])


@dataclasses.dataclass(frozen=True)
class ReferenceSet:
    """A set on disk: its folder and manifest; its specs and records are read on demand."""

    folder: Path
    manifest: Manifest

    @property
    def name(self) -> str:
        return self.manifest.name

    def specs(self) -> dict[str, dict]:
        """Each experiment's spec as summary.json keeps it, by experiment name."""
        return json.loads(self._read(SPECS))

    def records(self) -> Iterator[tuple[str, int, str, dict]]:
        """(experiment, seed, unit, record) for every record of the set, sources included."""
        for line in self._read(RECORDS).splitlines():
            entry = json.loads(line)
            where = f"{self.folder / RECORDS}: {entry['experiment']}/seed{entry['seed']}/{entry['unit']}"
            yield entry["experiment"], entry["seed"], entry["unit"], upgrade(entry["record"], where)

    def _read(self, name: str) -> bytes:
        path = self.folder / name
        try:
            data = path.read_bytes()
        except OSError as error:
            raise ReferenceError(f"{path}: cannot read ({error.strerror or error})") from None
        if hashlib.sha256(data).hexdigest() != self.manifest.files.get(name):
            raise ReferenceError(
                f"{path}: its SHA-256 is not the one {self.folder / MANIFEST} names (a copy cut short?)"
            )
        return lzma.decompress(data)


def available(root: Path = REFERENCE_ROOT) -> list[str]:
    """The names of the sets under ``root``."""
    return sorted(p.parent.name for p in root.glob(f"*/{MANIFEST}"))


def load(name: str | Path, root: Path = REFERENCE_ROOT) -> ReferenceSet:
    """The set named ``name`` under ``root``, or the set folder at path ``name``."""
    folder = Path(name)
    if not (folder / MANIFEST).is_file():
        folder = root / str(name)
    if not (folder / MANIFEST).is_file():
        raise ReferenceError(
            f"no reference set {str(name)!r}; valid sets: {available(root)}, or the path of a folder "
            f"holding a {MANIFEST}"
        )
    try:
        manifest = Manifest.from_json(read_json(folder / MANIFEST), folder / MANIFEST)
    except RecordError as error:
        raise ReferenceError(str(error)) from None
    return ReferenceSet(folder=folder, manifest=manifest)


def build(run_dir: str | Path, name: str, command: str, root: Path = REFERENCE_ROOT) -> ReferenceSet:
    """Packs the finished run in ``run_dir`` as the set ``root/name`` (replacing one there).

    ``command`` is the ``tatl run`` command that made the run, as the manifest names it.
    Refuses a run with units that did not finish and records that name no dynamics versions.
    A set built again keeps the fragile verdicts its manifest lists (they are written by hand).
    """
    run = RunDirectory(run_dir)
    try:
        summary = summary_data.read(run.summary)
    except FileNotFoundError:
        raise ReferenceError(f"{run.root}: no summary.json; finish its `tatl run` first") from None
    if summary.failures:
        raise ReferenceError(
            f"{run.root}: {len(summary.failures)} units did not finish (summary.json's failures); "
            "rerun its command until none fail"
        )
    preset, seeds = summary.preset, list(summary.seeds)
    lines, experiments, kernels = [], {}, collections.Counter()
    for experiment, entry in summary.experiments.items():
        methods = [m for m in summary.methods if m in entry.methods]  # the run's order, not the file's
        dynamics = set()
        for seed in seeds:
            for unit in [SOURCE_UNIT, *methods]:
                record = read_record(run.record_path(experiment, seed, unit))
                dynamics.add(json.dumps(record["dynamics"], sort_keys=True))
                kernels[record["kernels"]] += 1
                lines.append({"experiment": experiment, "seed": seed, "unit": unit, "record": record})
        if len(dynamics) != 1 or dynamics == {"{}"}:  # {}: a schema-1 record, which names none
            raise ReferenceError(
                f"{run.root}: the records of {experiment} name {len(dynamics)} sets of dynamics versions "
                f"({sorted(dynamics)}); one is needed: rerun it with this tatl-mj in a new folder"
            )
        experiments[experiment] = {
            "content_hash": content_hash(dict(entry.spec), preset),
            "dynamics": json.loads(dynamics.pop()),
            "methods": methods,
        }
    specs = {e: _in_run_order(dict(summary.experiments[e].spec), summary.methods) for e in experiments}
    folder = root / name
    fragile = load(folder).manifest.fragile_verdicts if (folder / MANIFEST).is_file() else ()
    data = {
        SPECS: _packed([json.dumps(specs)]),  # not sorted: a spec's method order is its pairs' order
        RECORDS: _packed(json.dumps(line, sort_keys=True, separators=(",", ":")) for line in lines),
    }
    for file, blob in data.items():
        write_atomic(folder / file, blob)
    manifest = Manifest(
        name=name,
        package_version=str(summary.versions["tatl-mj"]),
        schema_version=SCHEMA_VERSION,
        verdict_rule_version=summary.verdict_rule_version,  # the rule that judged the run
        preset=preset,
        seeds=tuple(seeds),
        command=command,
        experiments=experiments,
        kernels=dict(sorted(kernels.items())),
        versions=dict(summary.versions),
        records=len(lines),
        files={file: hashlib.sha256(blob).hexdigest() for file, blob in data.items()},
        fragile_verdicts=fragile,
    )
    write_json(folder / MANIFEST, manifest.to_json())
    return ReferenceSet(folder=folder, manifest=manifest)


def _in_run_order(spec: dict, order: list[str]) -> dict:
    """``spec`` with its methods in the run's order (summary.json's ``methods``): summary.json
    keeps a spec's tables sorted by name, the run listed them as the spec file does."""
    methods = spec["methods"]
    ranked = sorted(methods, key=lambda m: order.index(m) if m in order else len(order))
    return {**spec, "methods": {m: methods[m] for m in ranked}}


def _packed(lines: Any) -> bytes:
    return lzma.compress(("\n".join(lines) + "\n").encode(), preset=9 | lzma.PRESET_EXTREME)


def write_records(reference: ReferenceSet, out: str | Path, units: Any = None) -> int:
    """Writes the set's records (those whose unit is in ``units``, default all) into the run
    folder ``out``, as ``tatl run`` lays them out; returns how many."""
    run, written = RunDirectory(out), 0
    for experiment, seed, unit, record in reference.records():
        if units is None or unit in units:
            write_json(run.record_path(experiment, seed, unit), record)
            written += 1
    return written


def unpack(reference: ReferenceSet, out: str | Path) -> dict:
    """The set as a run folder in ``out``: its records, run.json and summary.json (built by this
    package's rule), which ``tatl plot`` reads; returns the summary. Sources come without
    their pickled artefacts, so ``tatl run`` on the folder computes them again."""
    run, manifest = RunDirectory(out), reference.manifest
    if run.manifest.exists() or run.summary.exists():
        raise ReferenceError(f"{run.root} holds a run already; unpack into a new folder")
    write_records(reference, out)
    write_json(run.manifest, {"preset": manifest.preset, "experiments": sorted(manifest.experiments)})
    specs = reference.specs()
    methods = list(dict.fromkeys(m for e in manifest.experiments for m in manifest.methods(e)))
    summary = summary_mod.build(
        run,
        specs=[specs[e] for e in manifest.experiments],
        preset=manifest.preset,
        seeds=list(manifest.seeds),
        methods=methods,
        versions=manifest.versions,
        kernels=manifest.kernels,
        reference=manifest.name,
        failures=[],
    )
    write_json(run.summary, summary)
    return summary
