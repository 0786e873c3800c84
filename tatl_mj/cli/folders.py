"""`tatl plot` and `tatl export`: a finished run folder's tables and figures, or its records as a CSV."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any


def add_plot(sub: Any) -> None:
    p = sub.add_parser("plot", help="figures and results table of a finished run")
    p.add_argument("dir", help="a `tatl run` output folder (its --out)")
    p.set_defaults(func=_plot)


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
