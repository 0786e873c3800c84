"""`tatl reference`: build, list or unpack reference sets."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from tatl_mj.cli import options


def add_reference(sub: Any) -> None:
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
    u.add_argument("--out", type=options.non_empty, required=True, help="a new folder")
    p.set_defaults(func=_reference)


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
