"""The `tatl` command: list, run, evaluate, plot, compare, reference, export, render, bench.

No GL library is loaded until a frame is drawn (``tatl_mj.gl``); `render` and
`bench` check the backend first, so every subcommand works on a headless machine.

This module is the parser and ``main``; each command's options and handler sit together in
their own module: ``tasks`` (list), ``run``, ``evaluate``, ``folders`` (plot, export), ``compare``,
``reference``, ``render`` (render, bench), over ``options`` (what their options share) and
``signals`` (stopping on SIGINT or SIGTERM).
"""

from __future__ import annotations

import argparse
import os
import sys

from tatl_mj.cli import compare, evaluate, folders, reference, render, run, tasks


def build_parser() -> argparse.ArgumentParser:
    from tatl_mj import __version__

    parser = argparse.ArgumentParser(prog="tatl", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}", help="print the version")
    sub = parser.add_subparsers(dest="command", required=True)
    tasks.add_list(sub)
    run.add_run(sub)
    evaluate.add_evaluate(sub)
    folders.add_plot(sub)
    compare.add_compare(sub)
    reference.add_reference(sub)
    folders.add_export(sub)
    render.add_render(sub)
    render.add_bench(sub)
    return parser


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
