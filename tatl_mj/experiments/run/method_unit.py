"""What a method unit computes, per experiment, seed and method: the paper's phase III.

``run_method``: for each target-sample budget of the preset, a transfer method learns
from the first ``n`` target transitions of the shared stream (``learned_policy``) and
its policy is evaluated on the target task; the points make its learning curve.

Target transitions are counted the same way for every method, per budget
(``target_transitions``): the shared-stream samples it learned from (a policy's
``samples_used`` where it reports one, e.g. TA-TL's apprentice under Algorithm 2;
otherwise the whole budget; none for a method whose ``data`` protocol draws its
own), plus every real-target transition the problem's hooks handed out or rolled
out for it (Algorithm 2's rollouts of the projected source policy, reset-protocol
and online data). The target transitions used to learn the mapping are reported
separately (``mapping_target_samples``), as the paper leaves them out of the
comparison because TA-TL and UMA-TL share them.
"""

from __future__ import annotations

import time
import warnings
from functools import partial
from typing import Any, Callable

import numpy as np

from tatl_mj.description import TaskDescription
from tatl_mj.experiments.results.records import SHARED_DATA
from tatl_mj.experiments.run.determinism import derive_seed
from tatl_mj.experiments.run.evaluation import evaluate_curve, steadiness
from tatl_mj.experiments.run.premises import PremiseObserver, fd_budgets
from tatl_mj.experiments.run.problems import Ledger, transfer_problem
from tatl_mj.experiments.run.source_unit import SourceArtifacts
from tatl_mj.experiments.spec import ExperimentSpec, Preset, methods_from_spec
from tatl_mj.transfer import method
from tatl_mj.transitions import Transitions


def _placebo(transfer: Any) -> bool:
    return method.contract(transfer).source == "placebo"


def learned_policy(
    spec: ExperimentSpec,
    preset: Preset,
    seed: int,
    transfer: Any,
    artifacts: SourceArtifacts,
    budget: int,
    problem: "method.TransferProblem | None" = None,
) -> Callable:
    """What ``transfer`` learns from the first ``budget`` target samples of this seed.

    The one path from a method to a policy: evaluation (``run_method``) and clips
    (``tatl render``) both call it, so a clip shows the evaluated policy.
    """
    if problem is None:
        uses_source = method.contract(transfer).uses_source
        problem = transfer_problem(spec, preset, artifacts, seed, placebo=_placebo(transfer), uses_source=uses_source)
    return transfer.learn(problem, artifacts.target_stream.head(budget))


def run_method(
    spec: ExperimentSpec,
    preset: Preset,
    seed: int,
    method_name: str,
    artifacts: SourceArtifacts,
    transfer: Any = None,
) -> dict:
    """One method's learning curve for one seed: return against target samples used.

    ``transfer`` is the method object (default: the spec's method of that name).
    """
    if transfer is None:
        transfer = methods_from_spec(spec, preset, [method_name])[method_name]
    ledger = Ledger()
    hooks = method.contract(transfer)
    problem = transfer_problem(spec, preset, artifacts, seed, ledger, _placebo(transfer), hooks.uses_source)
    # A method that uses no target samples (an oracle, a reference) learns the same
    # policy at every budget: it is learned and evaluated once and its point repeated.
    budgets = preset.target_budgets if hooks.uses_samples else preset.target_budgets[:1]
    learn = partial(learned_policy, spec, preset, seed, transfer, artifacts, problem=problem)
    points, policies = [], []
    for budget in budgets:
        point, policy = _learn_point(learn, budget, ledger, hooks)
        points.append(point)
        policies.append(policy)
    eval_seed = derive_seed(seed, spec.stream_name, "evaluation")  # same start states for every method
    observed = (artifacts.target_stream, derive_seed(seed, spec.stream_name, "premises"))
    curve = _evaluated_curve(spec, preset, problem.target, points, policies, eval_seed, observed)
    for budget in preset.target_budgets[len(curve) :]:
        curve.append(
            {
                **curve[-1],
                "samples": int(budget),
                "samples_used": 0,
                "learn_s": 0.0,
                "evaluate_s": 0.0,
                "premises_s": 0.0,
            }
        )
    final_used = getattr(policies[-1], "samples_used", None)
    return {
        "experiment": spec.name,
        "seed": seed,
        "method": method_name,
        "curve": curve,
        "final_return": curve[-1]["mean_return"],
        "random_return": artifacts.random_return,
        "data": hooks.data,
        # The target samples its mapping took (none for a method without a source).
        "mapping_target_samples": artifacts.mapping_target_samples if hooks.uses_source else 0,
        "algorithm2_samples": None if final_used is None else int(final_used),
    }


def _learn_point(
    learn: Callable[[int], Callable], budget: int, ledger: "Ledger", hooks: "method.Contract"
) -> tuple[dict, Callable]:
    """The policy ``learn(budget)`` learns and its curve point's learning fields."""
    ledger.new_budget()
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        policy = learn(budget)
    learn_s = time.perf_counter() - start
    used = method.samples_used(policy, budget) if hooks.uses_samples else 0
    stream = used if hooks.data == SHARED_DATA else 0
    point = {
        "samples": int(budget),
        # Algorithm 2 may stop before the budget: ``samples_used`` is what it kept.
        "samples_used": used,
        # Every real-target transition it learned from (stream, rollouts, own data).
        "target_transitions": stream + ledger.count if hooks.uses_samples else 0,
        # Of those, the policy rollouts' (Algorithm 2's U_M): the paper does not count them.
        "rollout_transitions": ledger.rollouts if hooks.uses_samples else 0,
        "learn_s": learn_s,
        # e.g. Algorithm 2's stopping rule not met within the budget
        "warnings": sorted({str(w.message) for w in caught}),
    }
    return point, policy


def _evaluated_curve(
    spec: ExperimentSpec,
    preset: Preset,
    target: TaskDescription,
    points: list[dict],
    policies: list[Callable],
    eval_seed: int,
    observed: tuple[Transitions, int] | None = None,
) -> list[dict]:
    """The curve's points with their evaluations: every budget's policy in one lockstep batch.

    A policy learned at several budgets (the same object) is evaluated once: its
    episodes are the same at each, from the same starts and noise. ``observed``: the
    target's sample stream and the seed of the premises' choice of visits; each point
    gets its policy's premises (None for a policy that is not TA-TL's).
    """
    distinct = list({id(policy): policy for policy in policies}.values())
    observer = None
    if observed is not None:
        fd = set(fd_budgets([p["samples"] for p in points]))
        blocks = {i for i, p in enumerate(distinct) for q, r in zip(points, policies) if r is p and q["samples"] in fd}
        observer = PremiseObserver(distinct, sorted(blocks), preset.evaluation_episodes, observed[1])
    start = time.perf_counter()
    evaluated = evaluate_curve(spec, preset, distinct, eval_seed, bool(target.steadiness), observer)
    evaluate_s = time.perf_counter() - start
    found: list[dict | None] = [None] * len(distinct)
    premises_s = 0.0
    if observer is not None and observer.active:
        start = time.perf_counter()
        used = {id(r): q["samples_used"] for q, r in zip(points, policies)}
        lengths = [n for _, n, _ in evaluated]
        found = observer.measurements(
            lengths,
            target,
            observed[0],
            [used[id(p)] for p in distinct],
            spec.target,
        )
        premises_s = time.perf_counter() - start
    steps = sum(int(n.sum()) for _, n, _ in evaluated)
    of = {id(policy): result for policy, result in zip(distinct, evaluated)}
    found_of = {id(policy): measured for policy, measured in zip(distinct, found)}
    curve: list[dict] = []
    timed: set[int] = set()
    for point, policy in zip(points, policies):
        returns, lengths, calls = of[id(policy)]
        weight = int(lengths.sum()) / max(steps, 1) if id(policy) not in timed else 0.0
        timed.add(id(policy))
        steady = {} if calls is None else {"steadiness": steadiness(target, *calls)}
        learned = {k: point[k] for k in ("samples", "samples_used", "target_transitions", "rollout_transitions")}
        curve.append(
            {
                **learned,
                "mean_return": float(np.mean(returns)),
                "returns": [float(r) for r in returns],
                "mean_steps": float(np.mean(lengths)),
                "steps": [int(n) for n in lengths],  # per episode: survival where episodes are capped
                **steady,  # per episode, where the target declares steadiness (the bicycle's roll)
                "learn_s": point["learn_s"],
                "warnings": point["warnings"],
                # The lockstep batch's time, shared out by episode steps (at a policy's first budget).
                "evaluate_s": evaluate_s * weight,
                # The premises' measuring after it (replays, fits), shared out the same way.
                "premises_s": premises_s * weight,
                # The theorem's premises on these episodes (TA-TL's policies; None for others).
                "premises": found_of[id(policy)],
            }
        )
    return curve
