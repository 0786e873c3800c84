"""What a run cost: its time per experiment and phase, and its work against its physics (the
MuJoCo substeps its units took, priced at raw ``mujoco.rollout`` speed), as ``tatl run`` prints
them at its end and keeps them in DIR/physics.json (docs/performance.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from tatl_mj import sampling
from tatl_mj.experiments.results.records import SOURCE_UNIT, RunDirectory, read_json


def timings(run_dir: str | Path) -> dict[str, dict[str, float]]:
    """Summed seconds per experiment and phase from a run's records (all seeds): source
    learning, target sampling, mapping, the random reference, and each method's learning,
    evaluation and premises (where it measured any). What ``tatl run`` prints at its end."""
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
        for part in ("learn", "evaluate", "premises"):
            spent = sum(float(p.get(f"{part}_s", 0.0)) for p in record.get("curve", []))
            if spent or part != "premises":
                phases[f"{unit} {part}"] = phases.get(f"{unit} {part}", 0.0) + spent
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
    counted = _physics_counts(run_dir)
    if previous is not None and {k: previous.get(k) for k in counted} == counted:
        return previous
    by_task = {}
    for key, n in sorted(counted["substeps"].items()):
        domain, task = key.split("/", 1)
        # The fastest of a few: one short timing moved the ratio by a fifth on a drifting machine.
        tries = [sampling.time_rollout(domain, task, seconds, threads=1) for _ in range(repeats)]
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
    """The breakdown as text: per experiment, its phases from the slowest, with their share; then
    the theorem's premises' share of the whole run's work (their measuring, timed on its own)."""
    lines = []
    for experiment, phases in table.items():
        total = sum(phases.values()) or 1.0
        lines.append(f"{experiment}: {total:.1f} s of work")
        for phase, seconds in sorted(phases.items(), key=lambda kv: -kv[1]):
            if seconds >= 0.05 * total:
                lines.append(f"  {phase:<32} {seconds:8.1f} s  {100 * seconds / total:4.0f}%")
    work = sum(sum(phases.values()) for phases in table.values())
    measured = sum(s for phases in table.values() for phase, s in phases.items() if phase.endswith(" premises"))
    if measured:
        lines.append(f"the theorem's premises: {measured:.1f} s of {work:.1f} s of work ({100 * measured / work:.1f}%)")
    return "\n".join(lines)


__all__ = ["format_physics", "format_timings", "physics_report", "timings"]
