"""`tatl evaluate`: your own policy (module:function, or a saved Stable-Baselines3 model) scored on
every condition of a spec, on its evaluation starts and seeds, normalised as its methods are."""

from __future__ import annotations

import argparse
import hashlib
import sys
from pathlib import Path
from typing import Any, Callable

import numpy as np

from tatl_mj.cli import options, signals
from tatl_mj.cli.run import _seeds as preset_seeds

MODEL_SUFFIX = ".zip"


def add_evaluate(sub: Any) -> None:
    p = sub.add_parser("evaluate", help="score your own policy on a spec's conditions and seeds (resumable)")
    p.add_argument("spec", help="an experiment spec or a sweep spec, e.g. tasks/sweeps/ip_to_flipped_ip_gain.toml")
    p.add_argument(
        "--policy",
        required=True,
        help="module:function (states (N, d) -> action values (N, m), or indices (N,) for a task that "
        "takes them), or a Stable-Baselines3 model file (.zip; the sb3 extra)",
    )
    p.add_argument(
        "--preset",
        default="paper",
        help="the spec's preset whose evaluation protocol and seeds score it (default: paper)",
    )
    p.add_argument(
        "--seeds", type=options.int_at_least(1), default=None, help="number of seeds (default: the preset's `seeds`)"
    )
    p.add_argument(
        "--first-seed",
        type=options.int_at_least(0),
        default=None,
        help="seeds are FIRST_SEED .. FIRST_SEED + SEEDS - 1 (default: the preset's `first_seed`; paper 200, held out)",
    )
    p.add_argument("--out", type=options.non_empty, required=True, help="output folder; rerunning resumes it")
    p.add_argument(
        "--context-in-observation",
        action="store_true",
        help="append the condition's context values to each state, as gym.make(id, context_in_observation=True) does",
    )
    p.add_argument(
        "--transitions",
        type=options.int_at_least(0),
        default=None,
        help="the target transitions the policy learned from (e.g. its training steps), for the plot's title",
    )
    p.add_argument("--name", default=None, help="the policy's name in tables and plots (default: the function or file)")
    p.add_argument("--command", default=None, help="the command that trained the policy, recorded in the manifest")
    p.set_defaults(func=_evaluate)


def _evaluate(args: argparse.Namespace) -> int:
    from tatl_mj.experiments.run import lock, scoring

    checked = _checked(args)
    if isinstance(checked, str):
        print(f"tatl evaluate: {checked}", file=sys.stderr)
        return 2
    try:
        with signals.stop_signals():
            scores = scoring.evaluate(checked, args.out, progress=print)
    except signals.Interrupted as stop:
        return signals.stopped("evaluate", stop, args.out)
    except (scoring.EvaluationError, lock.LockHeld) as error:
        print(f"tatl evaluate: {error}", file=sys.stderr)
        return 2
    except OSError as error:
        print(f"tatl evaluate: cannot write {error.filename or args.out}: {error.strerror or error}", file=sys.stderr)
        return 2
    _report(scores["rows"])
    print(f"wrote {Path(args.out) / scoring.SCORES} and {Path(args.out) / scoring.TABLE}")
    return 0


def _checked(args: argparse.Namespace) -> Any:
    """The evaluation ``tatl evaluate`` was given (``scoring.Evaluation``), or why it cannot run,
    in one line; nothing is written and no episode is run."""
    from tatl_mj.experiments import spec as spec_mod
    from tatl_mj.experiments.run import scoring

    problem = _policy_problem(args.policy)
    if problem:
        return problem
    try:
        spec = spec_mod.load_spec(args.spec)
        scoring.checked_preset(spec, args.preset)
    except (spec_mod.SpecError, scoring.EvaluationError) as error:
        return str(error)
    problem = options.check_out(args.out)
    if problem:
        return problem
    seeds = preset_seeds(args, [spec])
    if isinstance(seeds, str):
        return seeds
    loaded = _load_policy(args, spec)
    if isinstance(loaded, str):
        return f"--policy {args.policy}: {loaded}"
    policy, identity = loaded
    manifest = {
        "spec": str(args.spec),
        "spec_hash": spec_mod.content_hash(spec, args.preset),
        "experiment": spec.name,
        "conditions": [c.name for c in spec_mod.conditions(spec)],
        "preset": args.preset,
        "policy": identity,  # a model file's bytes (SHA-256), or a function's path and its module's bytes
        "policy_given": args.policy,
        "name": args.name or _default_name(args.policy),
        "context_in_observation": bool(args.context_in_observation),
        "transitions": args.transitions,
        "command": args.command,
    }
    return scoring.Evaluation(spec, args.preset, list(seeds), policy, manifest, bool(args.context_in_observation))


def _policy_problem(text: str) -> str | None:
    """Why ``--policy`` names neither a function nor a model file, or None; imports nothing."""
    if text.endswith(MODEL_SUFFIX):
        return None if Path(text).is_file() else f"--policy {text}: no such file"
    module, _, function = text.partition(":")
    if module and function:
        return None
    if Path(text).is_file():
        return f"--policy {text}: a model file must be a Stable-Baselines3 .zip"
    return f"--policy {text}: give module:function or a Stable-Baselines3 model file (.zip)"


def _default_name(text: str) -> str:
    return Path(text).stem if text.endswith(MODEL_SUFFIX) else text.rpartition(":")[2]


def _load_policy(args: argparse.Namespace, spec: Any) -> tuple[Callable, dict] | str:
    """The policy and what identifies it in the manifest, or why it cannot be used."""
    if args.policy.endswith(MODEL_SUFFIX):
        return _load_model(args, spec)
    from tatl_mj import plugins

    try:
        policy = plugins.load(args.policy, "policy")
    except ValueError as error:
        return str(error).removeprefix(f"policy {args.policy!r}: ")
    if not callable(policy):
        return f"{type(policy).__name__} is not callable (states (N, d) -> actions)"
    module = sys.modules[args.policy.partition(":")[0]]
    source = getattr(module, "__file__", None)
    return policy, {
        "kind": "function",
        "path": args.policy,
        "module_sha256": None if source is None else _sha256(source),
    }


def _load_model(args: argparse.Namespace, spec: Any) -> tuple[Callable, dict] | str:
    from tatl_mj.experiments import spec as spec_mod
    from tatl_mj.experiments.run import scoring
    from tatl_mj.experiments.run.sides import description_of

    try:
        from tatl_mj import sb3
    except ImportError as error:
        return str(error)
    condition = spec_mod.conditions(spec)[0]
    target = condition.target
    state_size = len(description_of(target).state_names)
    size = state_size + (len(scoring.context_values(condition)) if args.context_in_observation else 0)
    try:
        model = sb3.load_model(args.policy)
        policy = sb3.model_policy(model, target.domain, target.task, target.task_kwargs, size)
    except ValueError as error:
        return str(error)
    digest = sb3.file_sha256(args.policy)
    return policy, {"kind": "stable-baselines3", "algorithm": type(model).__name__, "sha256": digest}


def _sha256(path: str) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _report(rows: list[dict]) -> None:
    """Per condition: the mean return and the mean normalised score over the seeds."""
    by: dict[str, list[dict]] = {}
    for row in rows:
        by.setdefault(row["experiment"], []).append(row)
    for name, group in by.items():
        scores = [r["normalised"] for r in group if r["normalised"] is not None]
        score = f"{np.mean(scores):.3f}" if scores else "n/a"
        mean = np.mean([r["mean_return"] for r in group])
        print(f"{name}: mean return {mean:.1f}, normalised {score} (mean of {len(group)} seeds)")
