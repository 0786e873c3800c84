"""``tatl compare``: a user's methods against a reference set, on its protocol, without rerunning it.

The reference set (:mod:`tatl_mj.experiments.results.reference`) holds every built-in
method's records for its specs, preset and seeds. A comparison runs only the
user's method units and the per-seed source units they need, with the
reference's preset and seeds, into its own run folder; it then writes the
reference's method records beside them and builds the summary, tables, verdicts
and figures that ``tatl plot`` makes, for the user's methods among every
reference method.

Before any work, :func:`plan` refuses, in one line naming what differs and how
to fix it: a spec whose content differs from the one the reference was made from
(``spec.content_hash``), another preset or other seeds, a task whose dynamics
version differs, another record schema, a user method named like a reference
method, and a pair naming a method that is not there.

Transfer credit: a user names the source-free ablation (and the placebo) of each
of their methods on the command line (``--ablation mine=mine-no-source``), not in
the method: the pairs a verdict answers belong to the comparison, as a spec's own
pairs belong to the spec. They reach the verdict rule as a spec's own do: the
spec the summary reads gains a method table for each user method, with the
``ablation`` and ``placebo`` keys a spec's tables declare pairs with
(:func:`_summary_spec`; ``pairs.declared_pairs`` reads them), so the user's
methods also meet the spec's frozen best baseline.

Kernels: the user's units run with the reference's arithmetic kernels where this
machine can (``kernels.pin_to``); the records say which kernels computed them,
and where they differ from the reference's the results say so once and list the
verdicts the reference's manifest marks as moving with kernels.
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import json
import shutil
import tempfile
from pathlib import Path
from typing import Any

from tatl_mj.experiments import compare_report
from tatl_mj.experiments import compare_settings as settings_mod
from tatl_mj.experiments.report import plot
from tatl_mj.experiments.results import summary as summary_mod
from tatl_mj.experiments.results.records import (
    SCHEMA_VERSION,
    SOURCE_UNIT,
    RunDirectory,
    read_json,
    read_record,
    write_json,
)
from tatl_mj.experiments.results.reference import ReferenceSet
from tatl_mj.experiments.run import kernels as kernels_mod
from tatl_mj.experiments.run import runner
from tatl_mj.experiments.spec import (
    NOT_CONTENT,
    ExperimentSpec,
    conditions,
    content_hash,
    dynamics_versions,
    spec_to_dict,
)
from tatl_mj.transfer import roles

PAIR_KINDS = roles.PAIR_KEYS
COMPARISON = "compare.json"  # in --out: the reference it was compared against, and the user's methods
COSTS = (
    "wall_s",
    "fqi_s",
    "physics_substeps",
    "timings",
    "learn_s",
    "evaluate_s",
    "premises_s",
    "kernels",
    "blob_sha256",
    "schema_version",
)
"""Fields of a record that say what it cost or what computed it, not what it found: --check skips them."""


class CompareError(ValueError):
    """A comparison that cannot be made as asked; one line naming what differs and how to fix it."""


@dataclasses.dataclass(frozen=True)
class Plan:
    """A checked comparison: the reference, the experiments (sweeps expanded) to run, with a
    table for each built-in renamed, the user's methods by name (None: a built-in run with
    each spec's settings for it; {experiment: method object} where a settings file gives it
    settings per experiment), their declared pairs, and the settings file with what it set."""

    reference: ReferenceSet
    specs: tuple[ExperimentSpec, ...]
    methods: dict[str, Any]
    pairs: dict[str, tuple[tuple[str, str], ...]]
    settings: settings_mod.Settings | None = None
    settings_used: dict[str, dict[str, dict[str, Any]]] = dataclasses.field(default_factory=dict)

    @property
    def preset(self) -> str:
        return self.reference.manifest.preset

    @property
    def seeds(self) -> list[int]:
        return list(self.reference.manifest.seeds)


def _seed_text(seeds: Any) -> str:
    seeds = list(seeds)
    contiguous = seeds == list(range(seeds[0], seeds[-1] + 1)) if seeds else False
    return f"{seeds[0]}-{seeds[-1]}" if contiguous and len(seeds) > 2 else ", ".join(map(str, seeds))


def check_reference(reference: ReferenceSet, preset: str | None = None, seeds: list[int] | None = None) -> None:
    """Refuses a reference of another record schema, and a preset or seeds other than its own."""
    manifest, name = reference.manifest, reference.name
    if manifest.schema_version != SCHEMA_VERSION:
        raise CompareError(
            f"reference {name!r} holds records of schema {manifest.schema_version}; this tatl-mj writes schema "
            f"{SCHEMA_VERSION}: use a reference set made by this version (`tatl reference list`)"
        )
    if preset is not None and preset != manifest.preset:
        raise CompareError(
            f"--preset {preset}: reference {name!r} was run with preset {manifest.preset!r}; leave --preset out, "
            "or pick a reference of that preset (`tatl reference list`)"
        )
    if seeds is not None and list(seeds) != list(manifest.seeds):
        raise CompareError(
            f"seeds {_seed_text(seeds)}: reference {name!r} holds seeds {_seed_text(manifest.seeds)}; leave "
            "--seeds and --first-seed out, or pick the reference of those seeds (`tatl reference list`)"
        )


def check_spec(reference: ReferenceSet, spec: ExperimentSpec) -> None:
    """Refuses an experiment the reference does not hold, or holds with other content or dynamics."""
    manifest, name = reference.manifest, reference.name
    entry = manifest.experiments.get(spec.name)
    if entry is None:
        raise CompareError(
            f"{spec.path}: experiment {spec.name!r} is not in reference {name!r} (its experiments: "
            f"{sorted(manifest.experiments)}); compare only the specs it was made from"
        )
    spec.preset(manifest.preset)  # SpecError, naming the valid presets
    mine, theirs = content_hash(spec, manifest.preset), entry["content_hash"]
    if mine != theirs:
        raise CompareError(
            f"{spec.path}: the content of {spec.name!r} differs from the spec reference {name!r} was made from"
            f"{_first_difference(reference, spec)} (content hash {mine[:12]} against {theirs[:12]}): compare the "
            f"spec as tatl-mj "
            f"{manifest.package_version} ships it, or make a reference of your own from a run of yours "
            "(`tatl reference build`)"
        )
    dynamics = dynamics_versions(spec)
    if dynamics != entry["dynamics"]:
        raise CompareError(
            f"{spec.path}: its tasks' dynamics versions {dynamics} are not those of reference {name!r} "
            f"({entry['dynamics']}): its records do not hold for these tasks; use a reference made with them"
        )


def _content(table: Any, preset: str) -> Any:
    """A spec's content as :func:`spec.content_hash` hashes it, in JSON's plain types."""
    table = {k: v for k, v in dict(table).items() if k not in NOT_CONTENT}
    table["presets"] = {preset: table["presets"].get(preset)}
    return json.loads(json.dumps(table))


def _diff(mine: Any, theirs: Any, path: str = "") -> tuple[str, Any, Any] | None:
    """The first key path (in sorted order) at which two JSON values differ, with both values."""
    if isinstance(mine, dict) and isinstance(theirs, dict):
        for key in sorted(set(mine) | set(theirs)):
            where = f"{path}.{key}" if path else key
            if key not in mine or key not in theirs:
                return where, mine.get(key, "(absent)"), theirs.get(key, "(absent)")
            found = _diff(mine[key], theirs[key], where)
            if found:
                return found
        return None
    if isinstance(mine, list) and isinstance(theirs, list) and len(mine) == len(theirs):
        return next((d for i, (a, b) in enumerate(zip(mine, theirs)) if (d := _diff(a, b, f"{path}[{i}]"))), None)
    return None if mine == theirs and type(mine) is type(theirs) else (path, mine, theirs)


def _first_difference(reference: ReferenceSet, spec: ExperimentSpec) -> str:
    """`` at KEY (yours V, the reference's W)``, the first key whose value differs; empty where
    the reference holds no copy of the spec to compare with."""
    theirs = reference.specs().get(spec.name)
    if theirs is None:
        return ""
    preset = reference.manifest.preset
    found = _diff(_content(spec_to_dict(spec), preset), _content(theirs, preset))
    if found is None:
        return ""
    key, mine, other = found
    return f" at {key} (yours {json.dumps(mine)}, the reference's {json.dumps(other)})"


def plan(
    reference: ReferenceSet,
    specs: list[ExperimentSpec],
    methods: dict[str, Any],
    *,
    renamed: dict[str, str] | None = None,
    pairs: dict[str, list[tuple[str, str]]] | None = None,
    preset: str | None = None,
    seeds: list[int] | None = None,
    settings: settings_mod.Settings | None = None,
) -> Plan:
    """Checks everything a comparison needs, before any work; :class:`CompareError` if it cannot run.

    ``methods``: the user's, by name (a method object, or None for a built-in the
    reference does not hold); ``renamed``: new name -> a method each spec lists, run
    under the new name with that spec's settings for it (a variant table, as
    ``[methods.NEW] method = "ta-tl"`` makes, so it is paired as that method is);
    ``pairs``: per kind in :data:`PAIR_KINDS`, (one of those, its ablation or placebo:
    another of them or a reference method); ``settings``: a settings file's tables
    (``compare_settings``), each checked and applied here.
    """
    check_reference(reference, preset, seeds)
    expanded = [condition for spec in specs for condition in conditions(spec)]
    for spec in expanded:
        check_spec(reference, spec)
    renamed = dict(renamed or {})
    for new, base in renamed.items():
        lacking = next((s for s in expanded if base not in s.methods), None)
        if lacking is not None:
            raise CompareError(
                f"--methods {new}={base}: {lacking.path} lists no method {base!r} to rename (its methods: "
                f"{list(lacking.methods)})"
            )
    methods = {**methods, **dict.fromkeys(renamed)}
    held = {m for e in reference.manifest.experiments for m in reference.manifest.methods(e)}
    taken = sorted(set(methods) & held)
    if taken:
        raise CompareError(
            f"--methods: {taken[0]!r} names a method of reference {reference.name!r}; give yours a name of its own "
            "(its `name`)"
        )
    pairs = pairs or {}
    _check_pairs(reference, expanded, methods, pairs)
    specs_run = [_with_renamed(spec, renamed) for spec in expanded]
    used: dict[str, dict[str, dict[str, Any]]] = {}
    if settings is not None:
        parents = {c.name: spec.name for spec in specs for c in conditions(spec)}
        try:
            methods, used = settings_mod.apply(settings, methods, specs_run, parents)
        except ValueError as error:
            raise CompareError(str(error)) from None
    try:  # here, so that a method that cannot run is refused before --out is touched
        runner.check_methods(specs_run, reference.manifest.preset, methods)
    except runner.MethodError as error:
        raise CompareError(f"--methods: {error}") from None
    return Plan(
        reference=reference,
        specs=tuple(specs_run),
        methods=dict(methods),
        pairs={kind: tuple(tuple(p) for p in pairs.get(kind, ())) for kind in PAIR_KINDS},  # type: ignore[misc]
        settings=settings,
        settings_used=used,
    )


def _check_pairs(
    reference: ReferenceSet, specs: list[ExperimentSpec], methods: dict[str, Any], pairs: dict[str, Any]
) -> None:
    """Refuses a pair whose first method is not the user's, or whose second is neither the user's
    nor a method of the reference in every experiment."""
    unknown_kinds = sorted(set(pairs) - set(PAIR_KINDS))
    if unknown_kinds:
        raise ValueError(f"unknown pair kind {unknown_kinds[0]!r}; valid kinds: {list(PAIR_KINDS)}")
    for kind, listed in pairs.items():
        twice = sorted({m for m, _ in listed if [n for n, _ in listed].count(m) > 1})
        if twice:
            raise CompareError(f"--{kind}: {twice[0]!r} is given two; a method has one {kind}")
        for method, other in listed:
            if method not in methods:
                raise CompareError(
                    f"--{kind} {method}={other}: {method!r} is not one of --methods ({sorted(methods)}); "
                    f"a pair names one of your methods first"
                )
            missing = [
                s.name for s in specs if other not in methods and other not in reference.manifest.methods(s.name)
            ]
            if missing:
                raise CompareError(
                    f"--{kind} {method}={other}: {other!r} is neither one of --methods ({sorted(methods)}) nor a "
                    f"method of reference {reference.name!r} in {missing[0]}"
                )


def _with_renamed(spec: ExperimentSpec, renamed: dict[str, str]) -> ExperimentSpec:
    """``spec`` with a variant table per renamed method: its base's settings under the new name.
    Only the run sees it; the spec was checked against the reference as it was given."""
    tables = {new: {roles.VARIANT_KEY: base, **spec.methods[base]} for new, base in renamed.items()}
    return dataclasses.replace(spec, methods={**spec.methods, **tables}) if tables else spec


@dataclasses.dataclass(frozen=True)
class Outcome:
    """What a comparison wrote: its summary, the one short note on kernels (None when the
    user's records were computed with the reference's kernels; the long form is in
    compare.json), and what the reference's seeds can resolve."""

    summary: dict
    kernels_note: str | None
    paths: list[Path]
    resolution: str = ""


def _claim(out: Path, planned: Plan, detail: str | None) -> None:
    """Marks ``out`` as a comparison against the plan's reference, with its settings file (copied
    in, its hash recorded); refuses one against another reference or with other settings."""
    path = out / COMPARISON
    digest = planned.settings.sha256 if planned.settings is not None else None
    if path.exists():
        earlier = read_json(path)
        if earlier.get("reference") != planned.reference.name:
            raise CompareError(
                f"--out {out}: holds a comparison against reference {earlier.get('reference')!r}, not "
                f"{planned.reference.name!r}; use another --out"
            )
        if (earlier.get("settings") or {}).get("sha256") != digest:
            raise CompareError(
                f"--out {out}: holds a comparison made with other --settings (its records would not follow "
                "yours); use another --out"
            )
    out.mkdir(parents=True, exist_ok=True)
    settings = None
    if planned.settings is not None:
        shutil.copyfile(planned.settings.path, out / settings_mod.FILE)
        settings = {"file": settings_mod.FILE, "sha256": digest, "applied": planned.settings_used}
    write_json(
        path,
        {
            "reference": planned.reference.name,
            "methods": sorted(planned.methods),
            "settings": settings,
            "kernels": detail,
            "resolution": compare_report.resolution(len(planned.seeds)),
        },
    )


def _reference_records(planned: Plan, run: RunDirectory) -> collections.Counter[str]:
    """Writes the reference's method records of the planned experiments and seeds into ``run``
    (where not there yet); returns how many records each set of kernels computed."""
    wanted = {s.name: set(planned.reference.manifest.methods(s.name)) for s in planned.specs}
    counts: collections.Counter[str] = collections.Counter()
    for experiment, seed, unit, record in planned.reference.records():
        if unit in wanted.get(experiment, ()) and seed in planned.seeds:
            path = run.record_path(experiment, seed, unit)
            if not path.exists():
                write_json(path, record)
            counts[record["kernels"]] += 1
    return counts


def _fragile(planned: Plan) -> list[str]:
    return [
        f"{v['experiment']}: {v['method']} vs {v['versus']}"
        for v in planned.reference.manifest.fragile_verdicts
        if v["experiment"] in {s.name for s in planned.specs}
    ]


def kernels_detail(planned: Plan, computed: dict[str, int], pin: kernels_mod.Pin | None) -> str | None:
    """The long form of :func:`kernels_note`, kept in compare.json: both sets of kernels, why
    they could not be pinned, and the verdicts the reference marks as moving with them."""
    theirs = set(planned.reference.manifest.kernels)
    if set(computed) <= theirs and len(theirs) == 1:
        return None
    why = f" ({pin.why_not})" if pin is not None and pin.why_not else ""
    listed = "; ".join(_fragile(planned)) or "none are marked in its manifest"
    return (
        f"your units were computed with the arithmetic kernels {sorted(computed)}, reference "
        f"{planned.reference.name!r}'s with {sorted(theirs)}{why}: per-seed returns can differ, and these verdicts "
        f"are known to move with the kernels: {listed}"
    )


def kernels_note(planned: Plan, computed: dict[str, int], pin: kernels_mod.Pin | None) -> str | None:
    """One short line where the user's records were computed with other kernels than the
    reference's (:func:`kernels_detail` in compare.json has the rest); None where they were not."""
    if kernels_detail(planned, computed, pin) is None:
        return None
    fragile = len(_fragile(planned))
    moving = f"{fragile} verdict{'s' if fragile != 1 else ''} marked as moving with them"
    return (
        f"note: other arithmetic kernels than reference {planned.reference.name!r}'s; per-seed returns can "
        f"differ ({moving}; {COMPARISON} has the details)"
    )


def _workers(pin: kernels_mod.Pin | None) -> contextlib.AbstractContextManager:
    # No pin: the workers inherit this process's environment as `tatl run`'s do (an empty
    # Pin would clear OPENBLAS_CORETYPE where the machine sets it, and change the kernels).
    return kernels_mod.workers_under(pin) if pin is not None else contextlib.nullcontext()


def run(
    planned: Plan, out: str | Path, *, workers: int = 2, progress: bool = True, pin: kernels_mod.Pin | None = None
) -> Outcome:
    """Runs the plan's units into ``out`` (resumable, as ``tatl run``), adds the reference's
    records, and writes summary.json, results.md and the figures; returns what it wrote.

    Before anything is written, each user method's policy is rehearsed on a tiny problem of
    each pair of tasks (``runner.check_methods``): :class:`CompareError` where it answers
    other than its target takes. ``pin``: the kernels to run the user's units with
    (``kernels.pin_to`` of the reference's, None: this machine's own). Pinned units run in
    spawned workers, at least two, as the setting must be in place before a process loads
    numpy. Raises ``runner.RunFailed`` (after writing the rest) where a unit failed.
    """
    out = Path(out)
    try:
        runner.check_methods(list(planned.specs), planned.preset, planned.methods, planned.seeds[0], rehearse=True)
    except runner.MethodError as error:
        raise CompareError(f"--methods: {error}") from None
    if pin is not None and pin.env:
        workers = max(workers, 2)
    run_dir = RunDirectory(out)
    _claim(out, planned, None)
    failed: runner.RunFailed | None = None
    with _workers(pin):
        try:
            own = runner.run(
                list(planned.specs), planned.preset, planned.seeds, out, workers=workers, methods=planned.methods,
                progress=progress, rehearse=False,
            )  # fmt: skip
        except runner.RunFailed as error:
            failed, own = error, error.summary
    counts = _reference_records(planned, run_dir) + collections.Counter(own["kernels"])
    note, detail = kernels_note(planned, own["kernels"], pin), kernels_detail(planned, own["kernels"], pin)
    _claim(out, planned, detail)
    summary = summary_mod.build(
        run_dir,
        specs=[_summary_spec(s, planned) for s in planned.specs],
        preset=planned.preset,
        seeds=planned.seeds,
        methods=_methods(planned),
        versions=own["versions"],
        kernels=dict(counts),
        wall_s=own["wall_s"],
        workers=workers,
        executor="local",
        failures=own["failures"],
        compare={
            "reference": planned.reference.name,
            "reference_manifest": planned.reference.manifest.to_json(),
            "methods": sorted(planned.methods),
            "pairs": _pairs_json(planned),
            "kernels_note": note,
            "kernels_detail": detail,
        },
    )
    write_json(run_dir.summary, summary)
    paths = plot.plot(out)
    _head_results(out / "results.md", planned, note, summary)
    if failed is not None:
        raise failed
    resolution = compare_report.resolution(len(planned.seeds))
    return Outcome(summary=summary, kernels_note=note, paths=paths, resolution=resolution)


def _summary_spec(spec: ExperimentSpec, planned: Plan) -> dict:
    """The spec as the summary reads it, with a method table for each of the user's methods that
    carries its declared pairs (``roles.PAIR_KEYS``), so that the verdict rule pairs them as
    it pairs the spec's own (``pairs.declared_pairs``) and compares them with the spec's
    frozen best baseline. The spec itself, as checked against the reference, is unchanged."""
    table = spec_to_dict(spec)
    methods = {**table["methods"], **{name: dict(table["methods"].get(name) or {}) for name in planned.methods}}
    for kind, listed in planned.pairs.items():
        for method, other in listed:
            methods[method][kind] = other
    return {**table, "methods": methods}


def _pairs_json(planned: Plan) -> dict[str, list[list[str]]]:
    return {kind: [list(p) for p in listed] for kind, listed in planned.pairs.items()}


def _methods(planned: Plan) -> list[str]:
    """Every reference method of the planned experiments, then the user's."""
    manifest = planned.reference.manifest
    held = dict.fromkeys(m for s in planned.specs for m in manifest.methods(s.name))
    return [*held, *planned.methods]


def _head_results(path: Path, planned: Plan, note: str | None, summary: dict) -> None:
    """Opens results.md with what the tables compare (the reference and the user's methods),
    what its seeds can resolve, and the user's own verdicts (``compare_report.table``)."""
    manifest = planned.reference.manifest
    pairs = [f"`{m}` against `{o}` ({kind})" for kind, listed in planned.pairs.items() for m, o in listed]
    head = (
        f"Your methods ({', '.join(f'`{m}`' for m in planned.methods)}) against reference set "
        f"`{manifest.name}` (preset `{manifest.preset}`, seeds {_seed_text(manifest.seeds)}, records of tatl-mj "
        f"{manifest.package_version}, verdict rule {manifest.verdict_rule_version}), made by `{manifest.command}`. "
        + (f"Your pairs: {'; '.join(pairs)}." if pairs else "You declared no ablation or placebo of your own "
           "(`--ablation`, `--placebo`): your methods are ranked against the best baseline only.")
    )  # fmt: skip
    if planned.settings is not None:
        head += f" Settings per experiment: `{settings_mod.FILE}` (sha256 {planned.settings.sha256[:12]})."
    lines = [head, "", compare_report.resolution(len(planned.seeds)), ""]
    lines += [note.removeprefix("note: ").capitalize(), ""] if note else []
    lines += ["## Your verdicts", "", *compare_report.table(summary, list(planned.methods)), ""]
    path.write_text("\n".join(lines) + "\n" + path.read_text())


# --- tatl compare --check -------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Check:
    """Whether this machine reproduced a reference unit: ``differences`` lists the fields
    (paths into the record) whose values differ, empty when every one is equal bit for bit."""

    unit: str
    differences: tuple[str, ...]
    kernels_here: str
    kernels_reference: str

    @property
    def reproduced(self) -> bool:
        return not self.differences

    def __str__(self) -> str:
        if self.reproduced:
            return f"reproduced bit for bit: {self.unit} and its source unit, with kernels {self.kernels_here!r}"
        kernels = (
            f"the kernels differ: here {self.kernels_here!r}, the reference's {self.kernels_reference!r}"
            if self.kernels_here != self.kernels_reference
            else f"with the reference's own kernels ({self.kernels_here!r})"
        )
        shown = ", ".join(self.differences[:8]) + (" ..." if len(self.differences) > 8 else "")
        return f"not reproduced: {self.unit} differs in {len(self.differences)} fields ({shown}); {kernels}"


def cheapest_unit(planned: Plan) -> tuple[str, int, str]:
    """The (experiment, seed, method) of the planned experiments whose method unit and source
    unit took the least work in the reference, among those computed there (not shared copies)
    whose source and method both fit FQI by least squares, the arithmetic that other kernels
    change (any, where none does)."""
    sources: dict[tuple[str, int], dict] = {}
    methods: list[tuple[tuple[str, int, str], dict]] = []
    experiments = {s.name for s in planned.specs}
    for experiment, seed, unit, record in planned.reference.records():
        if experiment not in experiments:
            continue
        if unit == SOURCE_UNIT:
            sources[experiment, seed] = record
        elif "shared_from" not in record:
            methods.append(((experiment, seed, unit), record))

    def cost(entry: tuple[tuple[str, int, str], dict]) -> float:
        return float(entry[1]["wall_s"]) + float(sources[entry[0][:2]]["wall_s"])

    fitting = [m for m in methods if m[1]["fqi_s"] > 0 and sources[m[0][:2]]["fqi_s"] > 0]
    return min(fitting or methods, key=cost)[0]


def check(planned: Plan, unit: tuple[str, int, str] | None = None, pin: kernels_mod.Pin | None = None) -> Check:
    """Reruns one reference unit (default :func:`cheapest_unit`) and its source unit in a fresh
    folder, with ``pin``'s kernels, and compares its records with the reference's, field by field."""
    experiment, seed, method = unit or cheapest_unit(planned)
    spec = next(s for s in planned.specs if s.name == experiment)
    found = {
        u: record
        for e, s, u, record in planned.reference.records()
        if (e, s) == (experiment, seed) and u in (SOURCE_UNIT, method)
    }
    with tempfile.TemporaryDirectory(prefix="tatl-check-") as folder:
        with _workers(pin):
            # Two workers: each unit in a spawned process, which the pinned kernels reach.
            runner.run([spec], planned.preset, [seed], folder, workers=2, methods=[method], progress=False)
        run_dir = RunDirectory(folder)
        mine = {u: read_record(run_dir.record_path(experiment, seed, u)) for u in found}
    differences = tuple(f"{u}.{path}" for u in (SOURCE_UNIT, method) for path in _differences(mine[u], found[u]))
    return Check(
        unit=f"{experiment}/seed{seed}/{method}",
        differences=differences,
        kernels_here=mine[method]["kernels"],
        kernels_reference=found[method]["kernels"],
    )


def _differences(a: Any, b: Any, path: str = "") -> list[str]:
    """The paths at which ``a`` and ``b`` differ, skipping :data:`COSTS`."""
    if isinstance(a, dict) and isinstance(b, dict):
        keys = sorted((set(a) | set(b)) - set(COSTS))
        return [d for k in keys for d in _differences(a.get(k), b.get(k), f"{path}.{k}" if path else k)]
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in _differences(x, y, f"{path}[{i}]")]
    return [] if a == b and type(a) is type(b) else [path or "(record)"]
