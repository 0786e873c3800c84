"""`tatl plot` and `tatl export`: a finished run folder's tables and figures, or its records as a CSV;
`tatl plot` on `tatl evaluate` folders: their score panels (``report.scores``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any


def add_plot(sub: Any) -> None:
    p = sub.add_parser("plot", help="figures and results table of a finished run, or score panels of evaluations")
    p.add_argument(
        "dir",
        nargs="+",
        help="a `tatl run` output folder (its --out); or `tatl evaluate` folders, with at most one run folder "
        "of the same spec whose methods get panels too",
    )
    p.add_argument("--out", default=None, help="with evaluate folders: the figure (default: DIR/scores.png of one)")
    p.add_argument("--methods", default=None, help="with a run folder among evaluate folders: its methods drawn")
    p.set_defaults(func=_plot)


def _plot(args: argparse.Namespace) -> int:
    from tatl_mj.experiments.run import scoring

    if len(args.dir) > 1 or scoring.is_evaluation(args.dir[0]):
        return _plot_scores(args)
    if args.out is not None or args.methods is not None:
        print("tatl plot: --out and --methods go with `tatl evaluate` folders", file=sys.stderr)
        return 2
    return _plot_run(args.dir[0])


def _plot_scores(args: argparse.Namespace) -> int:
    from tatl_mj.experiments.report import scores

    out = args.out
    if out is None:
        if len(args.dir) > 1:
            print("tatl plot: give --out FIGURE.png for several folders", file=sys.stderr)
            return 2
        out = str(Path(args.dir[0]) / "scores.png")
    methods = None if args.methods is None else [m.strip() for m in args.methods.split(",") if m.strip()]
    try:
        path = scores.plot_scores(args.dir, out, methods)
    except (FileNotFoundError, ValueError, KeyError) as error:  # records.RecordError is a ValueError
        print(f"tatl plot: {error}", file=sys.stderr)
        return 2
    except OSError as error:
        print(f"tatl plot: cannot write {error.filename or out}: {error.strerror or error}", file=sys.stderr)
        return 2
    print(f"wrote {path}")
    return 0


def _plot_run(run_dir: str) -> int:
    from tatl_mj.experiments.report import plot

    try:
        paths = plot.plot(run_dir)
    except (FileNotFoundError, ValueError) as error:  # records.RecordError is a ValueError
        print(f"tatl plot: {error}", file=sys.stderr)
        return 2
    except (KeyError, TypeError, AttributeError) as error:
        print(
            f"tatl plot: {Path(run_dir) / 'summary.json'} is malformed ({type(error).__name__}: {error}); "
            f"rerun `tatl run` to rebuild it",
            file=sys.stderr,
        )
        return 2
    except OSError as error:
        print(f"tatl plot: cannot write {error.filename or run_dir}: {error.strerror or error}", file=sys.stderr)
        return 2
    for path in paths:
        print(f"wrote {path}")
    return 0


def add_export(sub: Any) -> None:
    p = sub.add_parser("export", help="a run's records as one tidy table (CSV)")
    p.add_argument("dir", help="a `tatl run` output folder (its --out)")
    p.add_argument("--format", choices=("csv",), default="csv", help="csv (Parquet would need pyarrow or pandas)")
    p.add_argument("--out", default=None, help="the table's path (default: DIR/export.csv, DIR/export-final.csv)")
    p.add_argument("--final", action="store_true", help="one row per method, seed and experiment: its largest budget's")
    p.set_defaults(func=_export)


def _export(args: argparse.Namespace) -> int:
    from tatl_mj.experiments.results import export, records

    try:
        path = export.export(args.dir, args.out, args.format, final=args.final)
    except (export.ExportError, records.RecordError) as error:
        print(f"tatl export: {error}", file=sys.stderr)
        return 2
    print(f"wrote {path}")
    return 0
