"""``tatl bench``'s options, their checks, and the run that emits each figure."""

from __future__ import annotations

import argparse
import json
from typing import Any

from tatl_mj.bench.contexts import MODES
from tatl_mj.bench.machine import machine, physics_tasks, reference
from tatl_mj.bench.report import print_record
from tatl_mj.bench.stepping import time_domain
from tatl_mj.bench.vector import time_vector
from tatl_mj.bench.work import measure_memory, time_fqi, time_render


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``tatl bench``."""
    parser.add_argument("--json", action="store_true", help="one JSON object per line, the summary last")
    parser.add_argument(
        "--domains",
        default=None,
        help="comma-separated subset of the suite's physics domains (default: all of them)",
    )
    parser.add_argument("--threads", type=int, default=2, help="MuJoCo threads for sampler and rollout (default 2)")
    parser.add_argument("--seconds", type=float, default=2.0, help="target length of each timing (default 2 s)")
    parser.add_argument(
        "--repeats",
        type=int,
        default=3,
        help="times each stepping figure is taken, in turn with the others; the fastest is kept (default 3)",
    )
    parser.add_argument(
        "--memory-transitions",
        type=int,
        default=1_000_000,
        help="cart-pole transitions collected for the memory figure (default 10^6; 0 skips it)",
    )
    parser.add_argument(
        "--fqi-transitions",
        type=int,
        default=100_000,
        help="cart-pole transitions FQI is fitted on (default 100 000; 0 skips it)",
    )
    parser.add_argument("--render-frames", type=int, default=60, help="frames for the render figure (0 skips it)")
    parser.add_argument(
        "--vector-tasks",
        default=None,
        help="comma-separated domain/task list for the vector-env figures (default: every physics task of "
        "the domains timed; empty skips them)",
    )
    parser.add_argument("--vector-envs", type=int, default=64, help="envs of each vector env (default 64)")
    parser.add_argument(
        "--contexts",
        choices=MODES,
        default=None,
        help="time the vector envs with a context per env: distinct (one each) or resample (a new one at each "
        "reset), beside raw rollout over the same per-env models (default: no contexts, beside SyncVectorEnv)",
    )


def vector_tasks(args: argparse.Namespace, domains: list[str]) -> list[tuple[str, str]]:
    """The ``domain/task`` pairs whose vector envs are timed (checked against the physics tasks)."""
    from tatl_mj import suite

    physics = [(d, t) for d, t in suite.ALL_TASKS if not suite.describe(d, t).discrete]
    if args.vector_tasks is None:
        return [(d, t) for d, t in physics if d in domains]
    chosen = [tuple(item.split("/", 1)) for item in str(args.vector_tasks).split(",") if item]
    unknown = [f"{c[0]}/{c[-1]}" for c in chosen if c not in physics]
    if unknown:
        raise ValueError(f"--vector-tasks: unknown {unknown}; valid: {[f'{d}/{t}' for d, t in physics]}")
    return chosen  # type: ignore[return-value]


def _check(args: argparse.Namespace) -> list[str]:
    physics = physics_tasks()
    domains = list(physics) if args.domains is None else [d for d in str(args.domains).split(",") if d]
    unknown = sorted(set(domains) - set(physics))
    if not domains:
        raise ValueError(f"--domains: none given; valid: {sorted(physics)}")
    if unknown:
        raise ValueError(f"--domains: unknown {unknown}; valid: {sorted(physics)}")
    if args.threads < 1:
        raise ValueError(f"--threads must be >= 1, got {args.threads}")
    if args.repeats < 1:
        raise ValueError(f"--repeats must be >= 1, got {args.repeats}")
    if args.vector_envs < 1:
        raise ValueError(f"--vector-envs must be >= 1, got {args.vector_envs}")
    if not args.seconds > 0:
        raise ValueError(f"--seconds must be > 0, got {args.seconds}")
    for name in ("memory_transitions", "fqi_transitions", "render_frames"):
        if getattr(args, name) < 0:
            raise ValueError(f"--{name.replace('_', '-')} must be >= 0, got {getattr(args, name)}")
    return domains


def run(args: argparse.Namespace) -> int:
    """Runs the benchmark; prints a table, or JSON lines with ``--json``. Returns 0."""
    try:
        domains = _check(args)
        vector_tasks(args, domains)
    except ValueError as error:
        print(f"tatl bench: {error}")
        return 2
    emit = (lambda record: print(json.dumps(record), flush=True)) if args.json else print_record
    info = machine()
    if not args.json:
        print(
            f"machine: {info['cpu']}, {info['cores']} cores ({info['usable_cores']} usable), "
            f"load {info['load_average_1min']}, mujoco {info['mujoco']}, threads {args.threads}"
        )
    physics = physics_tasks()
    per_domain = {domain: time_domain(domain, physics[domain], args, emit) for domain in domains}
    vector = {f"{d}/{t}": time_vector(d, t, args, emit) for d, t in vector_tasks(args, domains)}
    extra: dict[str, Any] = {}
    # Memory first, so that the process's peak RSS is not FQI's or the renderer's.
    if args.memory_transitions:
        extra["memory"] = measure_memory(args.memory_transitions, args.threads)
        emit({"kind": "memory", **extra["memory"]})
    if args.fqi_transitions:
        extra["fqi"] = time_fqi(args.fqi_transitions, args.threads)
        emit({"kind": "fqi", **extra["fqi"]})
    if args.render_frames:
        extra["render"] = time_render(args.render_frames)
        emit({"kind": "render", **extra["render"]})
    summary: dict[str, Any] = {
        "kind": "summary",
        "threads": args.threads,
        "vector_envs": args.vector_envs,
        "machine": info,
    }
    if reference()[0] in per_domain:
        summary.update(per_domain[reference()[0]])
    summary["domains"] = per_domain
    summary["vector"] = {task: figures for task, figures in vector.items() if figures}
    summary["fqi_fit_s"] = extra.get("fqi", {}).get("seconds")
    summary["render_fps"] = extra.get("render", {}).get("fps")
    summary["memory_peak_mb"] = extra.get("memory", {}).get("peak_mb")
    emit(summary)
    return 0
