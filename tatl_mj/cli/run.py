"""`tatl run`: its options, their checks, the run with stop signals caught, and its report."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from tatl_mj.cli import options, signals


def add_run(sub: Any) -> None:
    p = sub.add_parser("run", help="run transfer experiments (resumable)")
    p.add_argument("specs", nargs="+", help="experiment specs, e.g. tasks/*.toml")
    p.add_argument("--preset", default="smoke", help="named budget preset in the specs (default: smoke)")
    p.add_argument(
        "--seeds",
        type=options.int_at_least(1),
        default=None,
        help="number of seeds, >= 1 (default: the preset's `seeds`; smoke 2, paper 10)",
    )
    p.add_argument(
        "--first-seed",
        type=options.int_at_least(0),
        default=None,
        help="seeds run are FIRST_SEED .. FIRST_SEED + SEEDS - 1, >= 0 (default: the preset's "
        "`first_seed`; smoke 0, paper 200: held out, tuning used 0-9; 100-109 are retired as seen)",
    )
    p.add_argument("--out", type=options.non_empty, required=True, help="output folder; rerunning resumes it")
    p.add_argument("--workers", type=options.int_at_least(1), default=2, help="parallel work units, >= 1 (default: 2)")
    p.add_argument(
        "--executor",
        choices=("local", "ray"),
        default="local",
        help="local: a process pool on this machine; ray: a Ray cluster (default: local)",
    )
    p.add_argument("--address", default=None, help="Ray cluster address (with --executor ray)")
    p.add_argument(
        "--methods",
        default=None,
        help="comma-separated built-in methods and/or your own as module:Class (default: the methods each spec lists)",
    )
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    checked = _checked_run(args)
    if isinstance(checked, str):
        print(f"tatl run: {checked}", file=sys.stderr)
        return 2
    specs, seeds, methods = checked
    outcome = _execute(args, specs, seeds, methods)
    if isinstance(outcome, int):
        return outcome
    return _report(args, *outcome)


def _checked_run(args: argparse.Namespace) -> tuple[list, range, dict | None] | str:
    """The specs, seeds and methods ``tatl run`` was given, or why they cannot run; touches nothing."""
    from tatl_mj.experiments import spec as spec_mod

    resolved = [Path(p).resolve() for p in args.specs]
    twice = sorted({str(p) for p in args.specs if resolved.count(Path(p).resolve()) > 1})
    if twice:
        return f"spec given more than once: {', '.join(twice)}"
    try:
        specs = [spec_mod.load_spec(p) for p in args.specs]
        for s in specs:
            s.preset(args.preset)
    except spec_mod.SpecError as error:
        return str(error)
    names = [s.name for s in specs]
    clash = sorted({n for n in names if names.count(n) > 1})
    if clash:
        return (
            f"experiment name {clash[0]!r} is used by more than one spec: "
            f"{', '.join(s.path for s in specs if s.name == clash[0])}"
        )
    problem = options.check_out(args.out)
    if problem:
        return problem
    seeds = _seeds(args, specs)
    if isinstance(seeds, str):
        return seeds
    try:
        methods = options.parse_methods(args.methods, specs)
    except ValueError as error:
        return f"--methods: {error}"
    return specs, seeds, methods


def _execute(args: argparse.Namespace, specs: list, seeds: range, methods: dict | None) -> tuple[dict, Any] | int:
    """Runs the checked specs with SIGINT and SIGTERM caught: (summary, the RunFailed or None),
    or the exit status of a run that stopped or could not start (its message printed)."""
    from tatl_mj.experiments.results import records
    from tatl_mj.experiments.run import executors, lock, runner

    failed: runner.RunFailed | None = None
    try:
        with signals.stop_signals():
            summary = runner.run(
                specs,
                args.preset,
                seeds,
                args.out,
                workers=args.workers,
                executor=args.executor,
                address=args.address,
                methods=methods,
            )
    except runner.RunFailed as error:  # every other unit finished and the summary was written
        failed, summary = error, error.summary
    except signals.Interrupted as stop:
        return signals.stopped("run", stop, args.out)
    except (executors.ExecutorError, runner.RunFolderError) as error:  # raised before any work starts
        print(f"tatl run: {error}", file=sys.stderr)
        return 2
    except runner.MethodError as error:  # raised before any work starts
        print(f"tatl run: --methods: {error}", file=sys.stderr)
        return 2
    except lock.LockHeld as error:
        print(f"tatl run: {error}", file=sys.stderr)
        return 2
    except records.RecordError as error:
        print(f"tatl run: {error}", file=sys.stderr)
        return 2
    except OSError as error:
        where = error.filename or args.out
        print(f"tatl run: cannot write {where}: {error.strerror or error}", file=sys.stderr)
        return 2
    return summary, failed


def _report(args: argparse.Namespace, summary: dict, failed: Any) -> int:
    """Prints a finished run's timings, physics and notes; 1 when some unit failed, else 0."""
    from tatl_mj.experiments.results import records
    from tatl_mj.experiments.run import costs

    print("time per experiment and phase (all seeds, phases under 5% not shown):")
    print(costs.format_timings(costs.timings(args.out)))
    path = Path(args.out) / "physics.json"
    try:
        previous = records.read_json(path)  # reused as it is where no unit ran since
    except (FileNotFoundError, records.RecordError):
        previous = None
    physics = costs.physics_report(args.out, previous=previous if isinstance(previous, dict) else None)
    if physics is not previous:
        records.write_json(path, physics)
    print(costs.format_physics(physics))
    print(f"wrote {Path(args.out) / 'summary.json'} ({summary['wall_s']:.1f} s wall)")
    from tatl_mj.experiments.results import notes, summary_data

    for line in notes.notes(summary_data.Summary.from_json(summary)):
        print(line)
    if failed is not None:  # one line; each unit's is in summary.json's "failures" and its traceback file
        print(f"tatl run: {failed}", file=sys.stderr)
        return 1
    return 0


def _seeds(args: argparse.Namespace, specs: list) -> range | str:
    """--seeds and --first-seed, or where not given the preset's own (every spec's must agree);
    a string says why not."""
    chosen = {}
    for option, field in (("seeds", "seeds"), ("first_seed", "first_seed")):
        given = getattr(args, option)
        if given is not None:
            chosen[field] = given
            continue
        values = {getattr(s.preset(args.preset), field) for s in specs}
        if len(values) > 1:
            flag = "--" + option.replace("_", "-")
            return f"the specs' presets.{args.preset}.{field} differ ({sorted(values)}): give {flag}"
        chosen[field] = values.pop()
    return range(chosen["first_seed"], chosen["first_seed"] + chosen["seeds"])
