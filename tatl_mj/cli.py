"""The `tatl` command: list, run, plot, compare, reference, export, render, bench.

No GL library is loaded until a frame is drawn (``tatl_mj.gl``); `render` and
`bench` check the backend first, so every subcommand works on a headless machine.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any


def _list(args: argparse.Namespace) -> int:
    from tatl_mj import suite

    for domain, task in suite.ALL_TASKS:
        env = suite.load(domain, task, task_kwargs={"random": 0})
        state = env.reset().observation["state"]
        actions = suite.action_set(domain)
        line = f"{domain}/{task}: state dim {state.shape[0]}, actions {actions.ravel().tolist()}"
        if args.episode:
            import numpy as np

            rng = np.random.default_rng(0)
            total, steps, timestep = 0.0, 0, env.reset()
            while not timestep.last() and steps < args.max_steps:
                timestep = env.step(actions[rng.integers(len(actions))])
                total += timestep.reward
                steps += 1
            line += f", random-policy return {total:.3f} over {steps} steps"
        print(line)
        close = getattr(env, "close", None)
        if close:
            close()
    return 0


class Interrupted(BaseException):
    """SIGINT or SIGTERM arrived during a run (a BaseException, as KeyboardInterrupt is)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def _interrupt(signum: int, frame: object) -> None:
    from tatl_mj.experiments.run import workers

    # Stop the workers first: a pool's shutdown would otherwise wait for every running unit.
    workers.stop_children()
    raise Interrupted(signum)


def _check_out(out: str) -> str | None:
    """Why ``--out`` cannot hold a run, or None; touches nothing."""
    path = Path(out)
    if path.exists() and not path.is_dir():
        return f"--out {out}: exists and is not a directory"
    existing = next((p for p in [path, *path.parents] if p.exists()), Path("."))
    if not existing.is_dir():
        return f"--out {out}: {existing} is not a directory"
    if not os.access(existing, os.W_OK | os.X_OK):
        return f"--out {out}: {existing} is not writable"
    return None


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
    problem = _check_out(args.out)
    if problem:
        return problem
    seeds = _seeds(args, specs)
    if isinstance(seeds, str):
        return seeds
    try:
        methods = _methods(args.methods, specs)
    except ValueError as error:
        return f"--methods: {error}"
    return specs, seeds, methods


@contextlib.contextmanager
def _stop_signals() -> Iterator[None]:
    """SIGINT and SIGTERM stop the workers and raise :class:`Interrupted` within the block."""
    import signal

    previous = {sig: signal.signal(sig, _interrupt) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _stopped(command: str, stop: Interrupted, out: str) -> int:
    import signal

    name = signal.Signals(stop.signum).name
    # Leading newline: the progress bar's line is left unfinished.
    print(
        f"\ntatl {command}: stopped by {name}; finished units are kept in {out}, run the same command to resume",
        file=sys.stderr,
    )
    return 128 + stop.signum


def _execute(args: argparse.Namespace, specs: list, seeds: range, methods: dict | None) -> tuple[dict, Any] | int:
    """Runs the checked specs with SIGINT and SIGTERM caught: (summary, the RunFailed or None),
    or the exit status of a run that stopped or could not start (its message printed)."""
    from tatl_mj.experiments.results import records
    from tatl_mj.experiments.run import executors, lock, runner

    failed: runner.RunFailed | None = None
    try:
        with _stop_signals():
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
    except Interrupted as stop:
        return _stopped("run", stop, args.out)
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


def _methods(text: str | None, specs: list = ()) -> dict | None:
    """``ta-tl,rl,mypkg.mine:MyMethod`` -> {name: method object, or None for a built-in or a
    method the specs list}; None (no --methods): each spec's own ``[methods]``. ValueError in
    one line (``registry.parse_methods``)."""
    from tatl_mj.transfer import registry

    if text is None:
        return None
    methods = registry.parse_methods(text, [m for s in specs for m in s.methods])
    if not methods:
        raise ValueError("no methods given")
    return methods


def _plot(args: argparse.Namespace) -> int:
    from tatl_mj.experiments.report import plot

    try:
        paths = plot.plot(args.dir)
    except (FileNotFoundError, ValueError) as error:  # records.RecordError is a ValueError
        print(f"tatl plot: {error}", file=sys.stderr)
        return 2
    except (KeyError, TypeError, AttributeError) as error:
        print(
            f"tatl plot: {Path(args.dir) / 'summary.json'} is malformed ({type(error).__name__}: {error}); "
            f"rerun `tatl run` to rebuild it",
            file=sys.stderr,
        )
        return 2
    except OSError as error:
        print(f"tatl plot: cannot write {error.filename or args.dir}: {error.strerror or error}", file=sys.stderr)
        return 2
    for path in paths:
        print(f"wrote {path}")
    return 0


def _compare(args: argparse.Namespace) -> int:
    """``tatl compare``: checks everything first (one line and exit 2 if it cannot run), then runs
    the user's units and writes the tables, or with ``--check`` reruns one reference unit."""
    from tatl_mj.experiments import compare, compare_settings
    from tatl_mj.experiments import spec as spec_mod
    from tatl_mj.experiments.results import records, reference
    from tatl_mj.experiments.run import runner
    from tatl_mj.transfer import registry

    try:
        ref = reference.load(args.reference)
        specs = [spec_mod.load_spec(p) for p in args.specs]
        seeds = _compare_seeds(args, list(ref.manifest.seeds))
        if args.check is None and (not args.methods or not args.out):
            raise compare.CompareError("--methods and --out are needed: your methods (module:Class) and a folder")
        if args.check is None and (problem := _check_out(args.out)):
            raise compare.CompareError(problem)
        entries = [] if args.check is not None else [e.strip() for e in args.methods.split(",") if e.strip()]
        renamed = dict(_pair("methods", e) for e in entries if "=" in e)  # a built-in under a new name
        try:
            listed = [m for s in specs for m in s.methods]
            methods = registry.parse_methods(",".join(entries), listed, renames=True)
        except ValueError as error:
            raise compare.CompareError(f"--methods: {error}") from None
        pairs = {kind: [_pair(kind, text) for text in getattr(args, kind) or ()] for kind in compare.PAIR_KINDS}
        settings = compare_settings.read(args.settings) if args.settings else None
        plan = compare.plan(
            ref, specs, methods, renamed=renamed, pairs=pairs, preset=args.preset, seeds=seeds, settings=settings
        )
        unit = _unit(args.check) if args.check else None
    except (ValueError, FileNotFoundError) as error:  # CompareError, ReferenceError, SpecError, a plug-in's
        print(f"tatl compare: {error}", file=sys.stderr)
        return 2
    pin = _pin(ref)
    try:
        with _stop_signals():
            if args.check is not None:
                result = compare.check(plan, unit, pin)
                print(result)
                return 0 if result.reproduced else 1
            outcome = compare.run(plan, args.out, workers=args.workers, pin=pin)
    except Interrupted as stop:
        return _stopped("compare", stop, args.out or "its folder")
    except runner.RunFailed as error:
        print(f"tatl compare: {error}", file=sys.stderr)
        return 1
    except (records.RecordError, compare.CompareError) as error:
        print(f"tatl compare: {error}", file=sys.stderr)
        return 2
    for path in outcome.paths:
        print(f"wrote {path}")
    print(outcome.resolution)
    if outcome.kernels_note:
        print(outcome.kernels_note)
    return 0


def _pin(ref: Any) -> Any:
    """The reference's kernels for the user's units, where it names one set and this machine can."""
    from tatl_mj.experiments.run import kernels

    labels = sorted(ref.manifest.kernels)
    if len(labels) != 1:
        return kernels.Pin(env={}, kernels="", why_not=f"its records come from {len(labels)} sets of kernels")
    return kernels.pin_to(labels[0])


def _compare_seeds(args: argparse.Namespace, theirs: list[int]) -> list[int] | None:
    """The seeds --seeds and --first-seed ask for (the reference's where one is left out), or None."""
    if args.seeds is None and args.first_seed is None:
        return None
    first = theirs[0] if args.first_seed is None else args.first_seed
    return list(range(first, first + (len(theirs) if args.seeds is None else args.seeds)))


PAIR_FORMS = {
    "ablation": "YOURS=ABLATION, e.g. mine=mine-no-source",
    "placebo": "YOURS=PLACEBO, e.g. mine=mine-placebo",
    "methods": "NEW=BUILTIN, e.g. ta-tl-copy=ta-tl",
}


def _pair(option: str, text: str) -> tuple[str, str]:
    """``A=B`` given to ``--OPTION`` as (A, B); ValueError naming the form it takes."""
    left, _, right = text.partition("=")
    if not left.strip() or not right.strip():
        raise ValueError(f"--{option} {text}: expected {PAIR_FORMS[option]}")
    return left.strip(), right.strip()


def _unit(text: str) -> tuple[str, int, str]:
    experiment, seed, method = (text.split("/") + ["", "", ""])[:3]
    if not experiment or not seed.startswith("seed") or not seed[4:].isdigit() or not method:
        raise ValueError(f"--check {text}: expected EXPERIMENT/seedN/METHOD, e.g. mc_to_ip/seed100/rl")
    return experiment, int(seed[4:]), method


def _reference(args: argparse.Namespace) -> int:
    from tatl_mj.experiments.results import records, reference

    root = Path(args.root) if args.root else reference.REFERENCE_ROOT
    try:
        if args.action == "list":
            for name in reference.available(root):
                manifest = reference.load(name, root).manifest
                print(f"{name}: preset {manifest.preset}, seeds {list(manifest.seeds)}, {manifest.records:,} records")
            return 0
        if args.action == "build":
            built = reference.build(args.run_dir, args.name, args.command, root)
            print(f"wrote {built.folder} ({built.manifest.records:,} records)")
            return 0
        reference.unpack(reference.load(args.name, root), args.out)
    except (reference.ReferenceError, records.RecordError) as error:
        print(f"tatl reference: {error}", file=sys.stderr)
        return 2
    print(f"wrote {args.out}; `tatl plot {args.out}` draws its tables and figures")
    return 0


def _export(args: argparse.Namespace) -> int:
    from tatl_mj.experiments.results import export, records

    try:
        path = export.export(args.dir, args.out, args.format, final=args.final)
    except (export.ExportError, records.RecordError) as error:
        print(f"tatl export: {error}", file=sys.stderr)
        return 2
    print(f"wrote {path}")
    return 0


def _render(args: argparse.Namespace) -> int:
    from tatl_mj.experiments.report import clips

    try:
        path = clips.render_from_spec(
            args.spec,
            method=args.method,
            seed=args.seed,
            out=args.out,
            seconds=args.seconds,
            width=args.width,
            height=args.height,
            fps=args.fps,
            preset=args.preset,
            run_dir=args.run_dir,
            with_source=args.with_source,
        )
    except (ValueError, FileNotFoundError) as error:  # SpecError is a ValueError
        print(f"tatl render: {error}", file=sys.stderr)
        return 2
    print(f"wrote {path}")
    return 0


def _bench(args: argparse.Namespace) -> int:
    from tatl_mj import bench

    return bench.run(args)


def _int_at_least(low: int) -> Any:
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a whole number >= {low}, got {text!r}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"must be >= {low}, got {value}")
        return value

    parse.__name__ = f"integer >= {low}"  # what argparse names in its error
    return parse


def _non_empty(text: str) -> str:
    if not text.strip():
        raise argparse.ArgumentTypeError("must be a non-empty path")
    return text


def build_parser() -> argparse.ArgumentParser:
    from tatl_mj import __version__

    parser = argparse.ArgumentParser(prog="tatl", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}", help="print the version")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("list", help="list the suite's tasks")
    p.add_argument("--episode", action="store_true", help="also run one random-policy episode of each")
    p.add_argument("--max-steps", type=int, default=1000, help="cap on that episode's steps")
    p.set_defaults(func=_list)

    p = sub.add_parser("run", help="run transfer experiments (resumable)")
    p.add_argument("specs", nargs="+", help="experiment specs, e.g. tasks/*.toml")
    p.add_argument("--preset", default="smoke", help="named budget preset in the specs (default: smoke)")
    p.add_argument(
        "--seeds",
        type=_int_at_least(1),
        default=None,
        help="number of seeds, >= 1 (default: the preset's `seeds`; smoke 2, paper 10)",
    )
    p.add_argument(
        "--first-seed",
        type=_int_at_least(0),
        default=None,
        help="seeds run are FIRST_SEED .. FIRST_SEED + SEEDS - 1, >= 0 (default: the preset's "
        "`first_seed`; smoke 0, paper 100: held out, tuning used 0-4)",
    )
    p.add_argument("--out", type=_non_empty, required=True, help="output folder; rerunning resumes it")
    p.add_argument("--workers", type=_int_at_least(1), default=2, help="parallel work units, >= 1 (default: 2)")
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

    p = sub.add_parser("plot", help="figures and results table of a finished run")
    p.add_argument("dir", help="a `tatl run` output folder (its --out)")
    p.set_defaults(func=_plot)

    _compare_parser(sub)
    _reference_parser(sub)

    p = sub.add_parser("export", help="a run's records as one tidy table (CSV)")
    p.add_argument("dir", help="a `tatl run` output folder (its --out)")
    p.add_argument("--format", choices=("csv",), default="csv", help="csv (Parquet would need pyarrow or pandas)")
    p.add_argument("--out", default=None, help="the table's path (default: DIR/export.csv, DIR/export-final.csv)")
    p.add_argument("--final", action="store_true", help="one row per method, seed and experiment: its largest budget's")
    p.set_defaults(func=_export)

    p = sub.add_parser("render", help="render a clip of a method's policy on the target task")
    p.add_argument("spec", help="experiment spec, e.g. tasks/ip_to_flipped_ip.toml")
    p.add_argument("--method", default="ta-tl", help="a method the spec lists, or random (default: ta-tl)")
    p.add_argument("--seed", type=int, default=0, help="the run seed whose policy is filmed (default: 0)")
    p.add_argument("--out", required=True, help="clip path, .mp4 or .gif")
    p.add_argument("--seconds", type=float, default=5.0, help="clip length in simulated seconds (default: 5)")
    p.add_argument("--width", type=int, default=640, help="panel width in pixels (default: 640)")
    p.add_argument("--height", type=int, default=480, help="panel height in pixels (default: 480)")
    p.add_argument("--fps", type=int, default=30, help="clip frames per second (default: 30)")
    p.add_argument("--preset", default="smoke", help="budgets used when training is needed")
    p.add_argument("--run-dir", default=None, help="reuse a finished `tatl run` output folder")
    p.add_argument("--with-source", action="store_true", help="show the source system side by side")
    p.set_defaults(func=_render)

    p = sub.add_parser("bench", help="throughput of sampling paths, FQI and rendering")
    from tatl_mj import bench

    bench.add_arguments(p)
    p.set_defaults(func=_bench)
    return parser


def _compare_parser(sub: Any) -> None:
    p = sub.add_parser("compare", help="your methods against a reference set's, without rerunning it")
    p.add_argument("specs", nargs="+", help="experiment specs the reference was made from, e.g. tasks/*.toml")
    p.add_argument(
        "--methods",
        default=None,
        help="your methods, comma-separated, as module:Class; NEW=BUILTIN runs a built-in under a new name",
    )
    p.add_argument("--out", type=_non_empty, default=None, help="output folder; rerunning resumes it")
    p.add_argument(
        "--reference",
        default="paper-tuning",
        help="a reference set's name (`tatl reference list`) or folder (default: paper-tuning, the tuning "
        "seeds; compare on paper-heldout once your settings are frozen)",
    )
    p.add_argument(
        "--settings",
        default=None,
        metavar="FILE.toml",
        help="your plug-ins' settings per experiment: [METHOD.EXPERIMENT] tables of constructor arguments",
    )
    for kind in ("ablation", "placebo"):
        p.add_argument(
            f"--{kind}",
            action="append",
            metavar=f"YOURS={kind.upper()}",
            help=f"credit transfer: one of your methods and its {kind} (yours or the reference's); repeatable",
        )
    p.add_argument("--preset", default=None, help="must be the reference's (default: the reference's)")
    p.add_argument("--seeds", type=_int_at_least(1), default=None, help="must be the reference's (default: theirs)")
    p.add_argument("--first-seed", type=_int_at_least(0), default=None, help="must be the reference's (default)")
    p.add_argument("--workers", type=_int_at_least(1), default=2, help="parallel work units, >= 1 (default: 2)")
    p.add_argument(
        "--check",
        nargs="?",
        const="",
        default=None,
        metavar="EXPERIMENT/seedN/METHOD",
        help="rerun one reference unit (default: its cheapest) and report whether it is reproduced bit for bit",
    )
    p.set_defaults(func=_compare)


def _reference_parser(sub: Any) -> None:
    p = sub.add_parser("reference", help="build, list or unpack reference sets")
    p.add_argument("--root", default=None, help="the folder of sets (default: the package's reference/)")
    actions = p.add_subparsers(dest="action", required=True)
    b = actions.add_parser("build", help="pack a finished run folder as a reference set")
    b.add_argument("run_dir", help="a finished `tatl run` output folder")
    b.add_argument("--name", required=True, help="the set's name, e.g. paper-heldout")
    b.add_argument("--command", required=True, help="the `tatl run` command that made RUN_DIR, as typed")
    actions.add_parser("list", help="the sets there, with their preset and seeds")
    u = actions.add_parser("unpack", help="a set as a run folder that `tatl plot` reads")
    u.add_argument("name", help="a set's name or folder")
    u.add_argument("--out", type=_non_empty, required=True, help="a new folder")
    p.set_defaults(func=_reference)


RENDERING_COMMANDS = ("render", "bench")


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from tatl_mj import gl

    if args.command in RENDERING_COMMANDS:
        # Chosen and checked before any work, with a clear message; loaded at the first frame.
        try:
            gl.select_backend()
        except gl.GLBackendError as error:
            print(f"tatl {args.command}: {error}", file=sys.stderr)
            return 1
    try:
        return int(args.func(args) or 0)
    except BrokenPipeError:
        # The reader went away (`tatl list | head`): stop quietly, as Unix tools do.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141


if __name__ == "__main__":
    sys.exit(main())
