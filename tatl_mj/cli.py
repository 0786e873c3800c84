"""The `tatl` command: list, run, plot, render, bench.

The GL backend is chosen (``tatl_mj.gl``) before anything imports mujoco or
dm_control, so every subcommand works on a headless machine.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


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


def _run(args: argparse.Namespace) -> int:
    from tatl_mj.experiments import runner, spec as spec_mod

    try:
        specs = [spec_mod.load_spec(p) for p in args.specs]
        for s in specs:
            s.preset(args.preset)
    except spec_mod.SpecError as error:
        print(f"tatl run: {error}", file=sys.stderr)
        return 2
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    try:
        methods = _methods(args.methods)
    except ValueError as error:
        print(f"tatl run: --methods: {error}", file=sys.stderr)
        return 2
    summary = runner.run(
        specs, args.preset, seeds, args.out, workers=args.workers, executor=args.executor, address=args.address,
        methods=methods,
    )
    failures = summary.get("failures", [])
    print(f"wrote {Path(args.out) / 'summary.json'} ({summary['wall_s']:.1f} s wall)")
    for line in failures:
        print(f"FAILED {line}", file=sys.stderr)
    return 1 if failures else 0


def _methods(text: str | None) -> dict | None:
    """``ta-tl,rl,mypkg.mine:MyMethod`` -> {name: method object, or None for a built-in}.

    Built-ins run with the spec's settings for them; ``module:attr`` entries are
    imported, ``attr`` being a class (instantiated without arguments) or an
    instance whose ``name`` names it in the results. None (no --methods): each
    spec's own ``[methods]``.
    """
    import importlib

    from tatl_mj.transfer import registry
    from tatl_mj.transfer.method import TransferMethod

    if text is None:
        return None
    methods: dict = {}
    for entry in filter(None, (e.strip() for e in text.split(","))):
        if ":" not in entry:
            if entry not in registry.METHODS:
                raise ValueError(
                    f"unknown method {entry!r}; built-ins: {sorted(registry.METHODS)}, or module:Class"
                )
            methods[entry] = None
            continue
        module_name, _, attr = entry.partition(":")
        try:
            obj = getattr(importlib.import_module(module_name), attr)
        except (ImportError, AttributeError) as error:
            raise ValueError(f"cannot import {entry!r}: {error}") from None
        obj = obj() if isinstance(obj, type) else obj
        if not isinstance(obj, TransferMethod):
            raise ValueError(f"{entry!r} is not a TransferMethod (needs a name and learn(problem, samples))")
        methods[obj.name] = obj
    if not methods:
        raise ValueError("no methods given")
    return methods


def _plot(args: argparse.Namespace) -> int:
    from tatl_mj.experiments import plot

    try:
        paths = plot.plot(args.dir)
    except FileNotFoundError as error:
        print(f"tatl plot: {error}", file=sys.stderr)
        return 2
    for path in paths:
        print(f"wrote {path}")
    return 0


def _render(args: argparse.Namespace) -> int:
    from tatl_mj.experiments import clips

    try:
        path = clips.render_from_spec(
            args.spec, method=args.method, seed=args.seed, out=args.out, seconds=args.seconds,
            width=args.width, height=args.height, fps=args.fps, preset=args.preset, run_dir=args.run_dir,
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


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="tatl", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("list", help="list the suite's tasks")
    p.add_argument("--episode", action="store_true", help="also run one random-policy episode of each")
    p.add_argument("--max-steps", type=int, default=1000, help="cap on that episode's steps")
    p.set_defaults(func=_list)

    p = sub.add_parser("run", help="run transfer experiments (resumable)")
    p.add_argument("specs", nargs="+", help="experiment specs, e.g. tasks/*.toml")
    p.add_argument("--preset", default="smoke", help="named budget preset in the specs (default: smoke)")
    p.add_argument("--seeds", type=int, default=2, help="number of seeds (default: 2)")
    p.add_argument("--first-seed", type=int, default=0)
    p.add_argument("--out", required=True, help="output folder; rerunning resumes it")
    p.add_argument("--workers", type=int, default=2, help="parallel work units (default: 2)")
    p.add_argument("--executor", choices=("local", "ray"), default="local")
    p.add_argument("--address", default=None, help="Ray cluster address (with --executor ray)")
    p.add_argument("--methods", default=None,
                   help="comma-separated built-in methods and/or your own as module:Class "
                        "(default: the methods each spec lists)")
    p.set_defaults(func=_run)

    p = sub.add_parser("plot", help="figures and results table of a finished run")
    p.add_argument("dir")
    p.set_defaults(func=_plot)

    p = sub.add_parser("render", help="render a clip of a method's policy on the target task")
    p.add_argument("spec")
    p.add_argument("--method", default="ta-tl", help="a method the spec lists, or random (default: ta-tl)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", required=True, help="clip path, .mp4 or .gif")
    p.add_argument("--seconds", type=float, default=5.0)
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--height", type=int, default=480)
    p.add_argument("--fps", type=int, default=30)
    p.add_argument("--preset", default="smoke", help="budgets used when training is needed")
    p.add_argument("--run-dir", default=None, help="reuse a finished `tatl run` output folder")
    p.add_argument("--with-source", action="store_true", help="show the source system side by side")
    p.set_defaults(func=_render)

    p = sub.add_parser("bench", help="throughput of sampling paths, FQI and rendering")
    from tatl_mj import bench  # imports neither mujoco nor dm_control

    bench.add_arguments(p)
    p.set_defaults(func=_bench)
    return parser


RENDERING_COMMANDS = ("render", "bench")


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    import os

    from tatl_mj import gl

    if args.command in RENDERING_COMMANDS:
        try:
            gl.select_backend()
        except gl.GLBackendError as error:
            print(f"tatl {args.command}: {error}", file=sys.stderr)
            return 1
    elif "mujoco" not in sys.modules:
        # These commands never render: no GL library is needed, and a broken
        # MUJOCO_GL setting must not stop them (worker processes inherit this).
        os.environ["MUJOCO_GL"] = "disable"
        os.environ.pop("PYOPENGL_PLATFORM", None)
    try:
        return int(args.func(args) or 0)
    except BrokenPipeError:
        # The reader went away (`tatl list | head`): stop quietly, as Unix tools do.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141


if __name__ == "__main__":
    sys.exit(main())
