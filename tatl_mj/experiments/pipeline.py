"""What one work unit computes: the paper's three phases for one experiment and seed.

Phase I and II (``learn_source``): the source policy (FQI, or exact Q-iteration
for the grid world), the random-policy target data stream shared by every
method, and the inter-task mapping learned from random-policy samples of both
tasks. Phase III (``run_method``): for each target-sample budget of the preset,
a transfer method learns from the first ``n`` target transitions of that shared
stream and its policy is evaluated on the target task.

Target samples are counted the same way for every method: the number of target
transitions the method consumed (TA-TL: the apprentice's, Algorithm 2; UMA-TL
and RL: their target FQI batch). The target transitions used to learn the
mapping are reported separately (``mapping_target_samples``), as the paper
leaves them out of the comparison because TA-TL and UMA-TL share them.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
import zlib
from functools import partial
from typing import Any, Callable

import dm_env
import numpy as np

from tatl_mj import sampling, suite
from tatl_mj.experiments.spec import ExperimentSpec, Preset, Side
from tatl_mj.transfer import alignment, features, fqi, method
from tatl_mj.transitions import Transitions


def derive_seed(seed: int, *names: str) -> int:
    """A stable 32-bit seed for (seed, names...), identical across processes and hosts."""
    words = [seed] + [zlib.crc32(name.encode()) for name in names]
    return int(np.random.SeedSequence(words).generate_state(1)[0])


@dataclasses.dataclass(frozen=True)
class SourceArtifacts:
    """Everything phase III needs, shared by the methods of one experiment and seed."""

    source_q: Any
    mapping: Any
    target_stream: Transitions
    random_return: float
    mapping_target_samples: int
    mapping_source_samples: int
    source_samples: int
    timings: dict


# --- data -----------------------------------------------------------------------

def collect(side: Side, n: int, seed: int) -> Transitions:
    """``n`` random-policy transitions of one side, as its spec's ``data`` says."""
    if side.data.sampling == "episodes":
        return sampling.collect(
            side.domain, side.task, n, seed,
            task_kwargs=side.task_kwargs, max_episode_steps=side.data.episode_steps,
        )
    rng = np.random.default_rng(seed)
    low, high = np.asarray(side.data.state_low), np.asarray(side.data.state_high)
    states = rng.uniform(low, high, size=(n, len(low)))
    actions = rng.integers(len(suite.action_set(side.domain)), size=n)
    next_states = sampling.step_from(side.domain, side.task, states, actions, task_kwargs=side.task_kwargs)
    task = suite.load(side.domain, side.task, task_kwargs=side.task_kwargs).task
    absorbing = np.asarray(task.batch_absorbing(next_states), dtype=bool)
    return Transitions(
        states=states, actions=actions, rewards=task.batch_reward(next_states),
        next_states=next_states, absorbing=absorbing, last=np.ones(n, dtype=bool),
    )


def random_policy(domain: str, seed: int) -> Callable[[np.ndarray], np.ndarray]:
    """A uniformly random policy over the domain's discrete action set (batched)."""
    actions = suite.action_set(domain)
    rng = np.random.default_rng(seed)
    return lambda states: actions[rng.integers(len(actions), size=len(states))]


def evaluate(spec: ExperimentSpec, preset: Preset, policy: Callable, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-episode returns and lengths of ``policy`` on the target task."""
    target = spec.target
    return sampling.evaluate(
        target.domain, target.task, policy, preset.evaluation_episodes, seed,
        task_kwargs=target.task_kwargs, max_episode_steps=preset.evaluation_steps,
    )


# --- phases I and II ----------------------------------------------------------

def _regressor_spec(learner) -> dict:
    spec = {"kind": learner.regressor, "features": learner.features}
    if learner.regressor == "linear":
        spec["ridge"] = learner.ridge
    return spec


def _source_q(spec: ExperimentSpec, preset: Preset, seed: int) -> tuple[Any, int]:
    learner = spec.source_learning
    n_actions = len(suite.action_set(spec.source.domain))
    if learner.method == "q_iteration":
        from tatl_mj.suite import gridworld

        windy = spec.source.task == "windy"
        next_state, reward, absorbing, cells = gridworld.transition_model(windy=windy)
        return fqi.q_iteration(next_state, reward, absorbing, learner.gamma, cells=cells), 0
    data = collect(spec.source, preset.source_samples, derive_seed(seed, spec.name, "source-data"))
    regressor = fqi.make_regressor(
        {**_regressor_spec(learner), "seed": derive_seed(seed, spec.name, "source-fqi")}, data.state_dim,
    )
    q = fqi.fitted_q_iteration(data, n_actions, regressor, learner.gamma, learner.iterations)
    return q, len(data)


def _affine_mapping(spec: ExperimentSpec, target_dim: int) -> "alignment.AffineMapping":
    matrix = np.asarray(spec.mapping.matrix, dtype=np.float64)
    source_dim = len(suite.load(spec.source.domain, spec.source.task, task_kwargs=spec.source.task_kwargs)
                     .reset().observation["state"])
    if matrix.shape != (target_dim, source_dim):
        raise ValueError(
            f"{spec.path}: mapping.matrix must have {target_dim} rows (target state) of {source_dim} "
            f"numbers (source state), got shape {matrix.shape}"
        )
    offset = np.asarray(spec.mapping.offset or np.zeros(target_dim), dtype=np.float64)
    return alignment.AffineMapping(matrix, offset)


def learn_source(spec: ExperimentSpec, preset: Preset, seed: int) -> SourceArtifacts:
    """Phases I and II for one seed."""
    timings = {}
    start = time.perf_counter()
    source_q, source_samples = _source_q(spec, preset, seed)
    timings["source_learning_s"] = time.perf_counter() - start

    start = time.perf_counter()
    stream_size = max(max(preset.target_budgets), preset.alignment_samples)
    target_stream = collect(spec.target, stream_size, derive_seed(seed, spec.name, "target-data"))
    timings["target_sampling_s"] = time.perf_counter() - start

    start = time.perf_counter()
    if spec.mapping.kind == "identity":
        mapping, n_map_source, n_map_target = alignment.IdentityMapping(), 0, 0
    elif spec.mapping.kind == "affine":
        mapping, n_map_source, n_map_target = _affine_mapping(spec, target_stream.state_dim), 0, 0
    else:
        source_states = collect(
            spec.source, preset.alignment_samples, derive_seed(seed, spec.name, "alignment-source")
        ).states
        target_states = target_stream.states[: preset.alignment_samples]  # reused by the apprentice
        mapping = alignment.align_manifolds(
            source_states, target_states, n_neighbors=spec.mapping.n_neighbors, mu=spec.mapping.mu,
            rng=np.random.default_rng(derive_seed(seed, spec.name, "alignment")),
        )
        n_map_source, n_map_target = len(source_states), len(target_states)
    timings["mapping_s"] = time.perf_counter() - start

    start = time.perf_counter()
    returns, _ = evaluate(spec, preset, random_policy(spec.target.domain, derive_seed(seed, "random-policy")),
                          derive_seed(seed, spec.name, "evaluation"))
    timings["random_evaluation_s"] = time.perf_counter() - start
    return SourceArtifacts(
        source_q=source_q, mapping=mapping, target_stream=target_stream,
        random_return=float(np.mean(returns)), mapping_target_samples=n_map_target,
        mapping_source_samples=n_map_source, source_samples=source_samples, timings=timings,
    )


# --- phase III ----------------------------------------------------------------

def _source_step(source: Side, states: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """Algorithm 1's query of the source simulator, from states clipped to the source's state box.

    A mapped target state can fall outside the region the source system is
    defined on (beyond the mountain car's track); the query is made from the
    nearest state inside the box the source was learned on.
    """
    if source.data.sampling == "uniform":
        states = np.clip(states, source.data.state_low, source.data.state_high)
    return sampling.step_from(source.domain, source.task, states, actions, task_kwargs=source.task_kwargs)


def _action_values(domain: str) -> np.ndarray:
    """Action values as the learners see them: actuator values, or grid moves."""
    if domain == "gridworld":
        from tatl_mj.suite import gridworld

        return gridworld.MOVES.astype(np.float64)
    return np.asarray(suite.action_set(domain), dtype=np.float64)


def transfer_problem(spec: ExperimentSpec, artifacts: SourceArtifacts, seed: int) -> "method.TransferProblem":
    """The bundle a transfer method learns from (see ``tatl_mj.transfer.method``)."""
    source, target = spec.source, spec.target
    env = suite.load(target.domain, target.task, task_kwargs=target.task_kwargs)
    action_spec = env.action_spec()
    # A discrete target (the grid world) takes action indices; its apprentice
    # sees the moves [d_row, d_col] as action values.
    discrete = isinstance(action_spec, dm_env.specs.DiscreteArray)
    low = None if discrete else np.asarray(action_spec.minimum, dtype=np.float64)
    high = None if discrete else np.asarray(action_spec.maximum, dtype=np.float64)
    target_actions = _action_values(target.domain)
    state_dim = artifacts.target_stream.state_dim
    learner = spec.target_learning
    return method.TransferProblem(
        source_q=artifacts.source_q,
        mapping=artifacts.mapping,
        source_step=partial(_source_step, source),
        source_actions=_action_values(source.domain),
        target_actions=target_actions,
        target_low=low,
        target_high=high,
        target_discrete=discrete,
        apprentice_features=features.make_features(spec.apprentice.features, state_dim),
        regressor=_regressor_spec(learner),
        gamma=learner.gamma,
        iterations=learner.iterations,
        seed=derive_seed(seed, spec.name, "target-learning"),
        apprentice_ridge=spec.apprentice.ridge,
        # The apprentice's basis names the angle coordinates; its increments wrap there too.
        apprentice_periodic=tuple(spec.apprentice.features["periodic"])
        if "periodic" in spec.apprentice.features else None,
        adaptive_actions=np.asarray(spec.apprentice.adaptive_actions, dtype=np.float64).reshape(-1, 1)
        if spec.apprentice.adaptive_actions else None,
    )


def projected_source_policy(problem: "method.TransferProblem") -> Callable[[np.ndarray], np.ndarray]:
    """pi_hat(s_T) = pi*_S(chi_plus(s_T)) carried to the target's action of the same index (Algorithm 2)."""
    actions = np.asarray(problem.target_actions, dtype=np.float64).reshape(len(problem.target_actions), -1)

    def policy(states: np.ndarray) -> np.ndarray:
        index = problem.source_q.greedy(problem.mapping.chi_plus(states))
        return index if problem.target_discrete else actions[index]

    return policy


def utility_gap(spec: ExperimentSpec, preset: Preset, problem: "method.TransferProblem", seed: int):
    """Algorithm 2's |U_M(pi) - U_Mhat(pi)| / |U_M(pi)| for the projected source policy, or None.

    U_M is the projected policy's average return on the real target, U_Mhat the
    same policy's return when the apprentice stands in for the target (the
    target task's own reward and end conditions applied to the apprentice's
    predicted states, from the same kind of start states). The gap is relative,
    so ``apprentice.zeta`` is a fraction. The grid world has no vectorised
    reward model, so Algorithm 2 is not run there (None): TA-TL then fits its
    apprentice on the whole budget.
    """
    target = spec.target
    kwargs = {**target.task_kwargs, "random": derive_seed(seed, spec.name, "algorithm2-starts")}
    env = suite.load(target.domain, target.task, task_kwargs=kwargs)
    task = getattr(env, "task", None)
    if not hasattr(task, "batch_reward"):
        return None
    starts = np.stack([env.reset().observation["state"] for _ in range(preset.evaluation_episodes)])
    projected = projected_source_policy(problem)
    u_true = float(np.mean(evaluate(spec, preset, projected, derive_seed(seed, spec.name, "evaluation"))[0]))
    actions = np.asarray(problem.target_actions, dtype=np.float64).reshape(len(problem.target_actions), -1)

    def gap(apprentice_model) -> float:
        states, total = starts.copy(), np.zeros(len(starts))
        alive = np.ones(len(starts), dtype=bool)
        with np.errstate(all="ignore"):
            for _ in range(preset.evaluation_steps):
                action = projected(states)
                states = apprentice_model.predict(states, action if action.ndim == 2 else actions[action])
                if not np.all(np.isfinite(states)):
                    return 1e300  # the apprentice diverged: as far from the target as can be
                total += np.where(alive, task.batch_reward(states), 0.0)
                alive &= ~np.asarray(task.batch_absorbing(states), dtype=bool)
                if not alive.any():
                    break
        u_hat = float(total.mean())
        return abs(u_true - u_hat) / max(abs(u_true), 1e-9)

    return gap


def run_method(
    spec: ExperimentSpec, preset: Preset, seed: int, method_name: str, artifacts: SourceArtifacts,
    methods: dict | None = None,
) -> dict:
    """One method's learning curve for one seed: return against target samples used."""
    methods = method.METHODS if methods is None else methods
    if method_name not in methods:
        raise ValueError(f"unknown method {method_name!r}; valid methods: {sorted(methods)}")
    transfer = methods[method_name]
    problem = transfer_problem(spec, artifacts, seed)
    if method_name == "ta-tl":
        gap = utility_gap(spec, preset, problem, seed)
        if gap is not None:
            problem = dataclasses.replace(
                problem, utility_gap=gap, zeta=spec.apprentice.zeta, apprentice_batch=preset.target_budgets[0],
            )
    eval_seed = derive_seed(seed, spec.name, "evaluation")  # same start states for every method
    curve = []
    for budget in preset.target_budgets:
        start = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            policy = transfer.learn(problem, artifacts.target_stream.head(budget))
        learn_s = time.perf_counter() - start
        start = time.perf_counter()
        returns, lengths = evaluate(spec, preset, policy, eval_seed)
        curve.append({
            "samples": int(budget),
            # Algorithm 2 may stop before the budget; the curve still counts the budget.
            "samples_used": int(getattr(policy, "samples_used", None) or budget),
            "mean_return": float(np.mean(returns)),
            "returns": [float(r) for r in returns],
            "mean_steps": float(np.mean(lengths)),
            "learn_s": learn_s,
            # e.g. Algorithm 2's stopping rule not met within the budget
            "warnings": sorted({str(w.message) for w in caught}),
            "evaluate_s": time.perf_counter() - start,
        })
    return {
        "experiment": spec.name,
        "seed": seed,
        "method": method_name,
        "curve": curve,
        "final_return": curve[-1]["mean_return"],
        "random_return": artifacts.random_return,
        "mapping_target_samples": artifacts.mapping_target_samples,
        "algorithm2_samples": curve[-1]["samples_used"] if method_name == "ta-tl" else None,
    }
