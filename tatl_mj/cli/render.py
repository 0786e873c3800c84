"""`tatl render` and `tatl bench`: the commands that draw frames (``main`` checks the GL backend first)."""

from __future__ import annotations

import argparse
import sys
from typing import Any


def add_render(sub: Any) -> None:
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


def add_bench(sub: Any) -> None:
    p = sub.add_parser("bench", help="throughput of sampling paths, FQI and rendering")
    from tatl_mj import bench

    bench.add_arguments(p)
    p.set_defaults(func=_bench)


def _bench(args: argparse.Namespace) -> int:
    from tatl_mj import bench

    return bench.run(args)
