"""`tatl compare`: your methods against a reference set's, its options and their checks."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from tatl_mj.cli import options, signals


def add_compare(sub: Any) -> None:
    p = sub.add_parser("compare", help="your methods against a reference set's, without rerunning it")
    p.add_argument("specs", nargs="+", help="experiment specs the reference was made from, e.g. tasks/*.toml")
    p.add_argument(
        "--methods",
        default=None,
        help="your methods, comma-separated, as module:Class; NEW=BUILTIN runs a built-in under a new name",
    )
    p.add_argument("--out", type=options.non_empty, default=None, help="output folder; rerunning resumes it")
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
    p.add_argument(
        "--seeds", type=options.int_at_least(1), default=None, help="must be the reference's (default: theirs)"
    )
    p.add_argument("--first-seed", type=options.int_at_least(0), default=None, help="must be the reference's (default)")
    p.add_argument("--workers", type=options.int_at_least(1), default=2, help="parallel work units, >= 1 (default: 2)")
    p.add_argument(
        "--check",
        nargs="?",
        const="",
        default=None,
        metavar="EXPERIMENT/seedN/METHOD",
        help="rerun one reference unit (default: its cheapest) and report whether it is reproduced bit for bit",
    )
    p.set_defaults(func=_compare)


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
        if args.check is None and (problem := options.check_out(args.out)):
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
        with signals.stop_signals():
            if args.check is not None:
                result = compare.check(plan, unit, pin)
                print(result)
                return 0 if result.reproduced else 1
            outcome = compare.run(plan, args.out, workers=args.workers, pin=pin)
    except signals.Interrupted as stop:
        return signals.stopped("compare", stop, args.out or "its folder")
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
