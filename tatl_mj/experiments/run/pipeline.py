"""What one work unit computes: the paper's three phases for one experiment and seed.

Phase I and II (``learn_source``): the source policy (FQI, or exact Q-iteration
for a task with a known model), the random-policy target data stream shared by every
method, and the inter-task mapping learned from random-policy samples of both
tasks. Phase III (``run_method``): for each target-sample budget of the preset,
a transfer method learns from the first ``n`` target transitions of that shared
stream and its policy is evaluated on the target task.

Target transitions are counted the same way for every method, per budget
(``target_transitions``): the shared-stream samples it learned from (a policy's
``samples_used`` where it reports one, e.g. TA-TL's apprentice under Algorithm 2;
otherwise the whole budget; none for a method whose ``data`` protocol draws its
own), plus every real-target transition the problem's hooks handed out or rolled
out for it (Algorithm 2's rollouts of the projected source policy, reset-protocol
and online data). Algorithm 2's rollouts start from their own start states, never
the evaluation's. The target transitions used to learn the mapping are reported
separately (``mapping_target_samples``), as the paper leaves them out of the
comparison because TA-TL and UMA-TL share them.
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
import warnings
import zlib
from functools import cache, partial
from typing import Any, Callable, Iterator

import numpy as np
import threadpoolctl

from tatl_mj import sampling, suite
from tatl_mj.description import TaskDescription
from tatl_mj.experiments.results.records import STREAM_DATA
from tatl_mj.experiments.spec import ExperimentSpec, Preset, Side, methods_from_spec
from tatl_mj.transfer import apprentice, fqi, mappings, method, tabular_q
from tatl_mj.transfer.methods import horizon
from tatl_mj.transfer.placebo import placebo_q
from tatl_mj.transitions import Transitions


@contextlib.contextmanager
def one_thread() -> Iterator[None]:
    """One thread, for a unit's whole work (and a clip's training), as Ray runs a one-CPU task.

    One BLAS/OpenMP thread: a record must not depend on the executor or the machine's
    core count (a sum's last bit can flip with the thread count, and chaotic targets
    amplify it). One MuJoCo thread: the numbers would be the same on more, but a run's
    units already fill the cores, and their thread pools would wait on each other.
    """
    with threadpoolctl.threadpool_limits(limits=1), sampling.mujoco_threads(1):
        yield


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
    mapping_record: dict | None = None  # the learned or given map's coefficients, for the records


# --- data -----------------------------------------------------------------------


def random_transitions(side: Side, n: int, seed: int) -> Transitions:
    """``n`` random-policy transitions of one side, as its spec's ``data`` says."""
    if side.data.sampling == "episodes":
        return sampling.collect(
            side.domain,
            side.task,
            n,
            seed,
            task_kwargs=side.task_kwargs,
            max_episode_steps=side.data.episode_steps,
        )
    rng = np.random.default_rng(seed)
    low, high = np.asarray(side.data.state_low), np.asarray(side.data.state_high)
    states = rng.uniform(low, high, size=(n, len(low)))
    return one_step(side, states, rng.integers(description_of(side).n_actions, size=n))


def one_step(side: Side, states: np.ndarray, actions: np.ndarray, reward: Callable | None = None) -> Transitions:
    """One-step transitions of one side's real simulator from ``states`` under action indices
    ``actions``, scored by its own reward and end condition (``reward``: ``_target_reward(side)``)."""
    reward = _target_reward(side) if reward is None else reward
    if reward is None:
        raise ValueError(f"{side.domain}/{side.task} has no reward to score one-step transitions with")
    next_states = sampling.step_from(side.domain, side.task, states, actions, task_kwargs=side.task_kwargs)
    rewards, absorbing = reward(states, actions, next_states)
    return Transitions(states, actions, rewards, next_states, absorbing, np.ones(len(states), dtype=bool))


def description_of(side: Side) -> TaskDescription:
    """The description of one side's task (``suite.describe``)."""
    return suite.describe(side.domain, side.task, side.task_kwargs)


def random_policy(side: Side, seed: int) -> Callable[[np.ndarray], np.ndarray]:
    """A uniformly random policy over the task's discrete action set (batched):
    actuator values, or indices for a task that takes indices."""
    description = description_of(side)
    actions = np.arange(description.n_actions) if description.discrete else description.action_values
    rng = np.random.default_rng(seed)
    return lambda states: actions[rng.integers(len(actions), size=len(states))]


def target_returns(spec: ExperimentSpec, preset: Preset, policy: Callable, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-episode returns and lengths of ``policy`` on the target task."""
    return _on_target(spec, preset, [policy], seed)[0]


def _on_target(
    spec: ExperimentSpec, preset: Preset, policies: list[Callable], seed: int, joint: sampling.Joint | None = None
) -> list[tuple[np.ndarray, np.ndarray]]:
    target = spec.target
    return sampling.evaluate_policies(
        target.domain,
        target.task,
        policies,
        preset.evaluation_episodes,
        seed,
        task_kwargs=target.task_kwargs,
        max_episode_steps=preset.evaluation_steps,
        joint=joint,
    )


def evaluate_curve(
    spec: ExperimentSpec, preset: Preset, policies: list[Callable], seed: int, record: bool
) -> list[tuple[np.ndarray, np.ndarray, list | None]]:
    """Each policy's per-episode returns and lengths on the target task, from the same starts,
    all in one lockstep batch (a learning curve's budgets), and with ``record`` each one's
    per-episode (states, action values) lists for steadiness."""
    together = horizon.shared_decisions(policies) or sampling.one_by_one(policies)
    calls: list[list[tuple[np.ndarray, np.ndarray]]] = [[] for _ in policies]

    def joint(blocks: list[int], states: list[np.ndarray]) -> list[np.ndarray]:
        values = together(blocks, states)
        if record:
            for b, s, v in zip(blocks, states, values):
                calls[b].append((np.array(s, dtype=np.float64), np.array(v, dtype=np.float64)))
        return values

    results = _on_target(spec, preset, policies, seed, joint)
    return [(r, n, per_episode(c, n) if record else None) for (r, n), c in zip(results, calls)]


def per_episode(
    calls: list[tuple[np.ndarray, np.ndarray]], lengths: np.ndarray
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Each episode's states (T_i, d) and action values (T_i, m), in step order, from a
    policy's lockstep calls: at step t its live episodes are, in order, those whose
    length exceeds t."""
    rows: list[list[int]] = [[] for _ in lengths]
    for t in range(len(calls)):
        for j, i in enumerate(np.flatnonzero(lengths > t)):
            rows[i].append(j)
    states = [np.stack([calls[t][0][j] for t, j in enumerate(r)]) for r in rows]
    values = [np.stack([np.atleast_1d(calls[t][1][j]) for t, j in enumerate(r)]) for r in rows]
    return states, values


def steadiness(description: TaskDescription, states: list[np.ndarray], values: list[np.ndarray]) -> dict:
    """Per episode: the RMS over its steps of each ``description.steadiness`` state entry (named
    ``<entry>_rms``, in the state's units) and the mean absolute actuator value after clipping
    (``mean_abs_action``). The steps are those the episode lasted: its balanced time, where a
    fall ends it."""
    out: dict[str, list[float]] = {}
    for name in description.steadiness:
        k = description.state_names.index(name)
        out[f"{name}_rms"] = [float(np.sqrt(np.mean(s[:, k] ** 2))) for s in states]
    if not description.discrete:
        low, high = description.action_low, description.action_high
        out["mean_abs_action"] = [float(np.mean(np.abs(np.clip(v, low, high)))) for v in values]
    return out


# --- phases I and II ----------------------------------------------------------


def _source_q(spec: ExperimentSpec, preset: Preset, seed: int) -> tuple[Any, int]:
    learner = spec.source_learning
    source = description_of(spec.source)
    if learner.method == "q_iteration":  # exact, on the task's known model (checked at spec load)
        assert source.known_model is not None
        next_state, reward, absorbing, cells = source.known_model()
        return tabular_q.q_iteration(next_state, reward, absorbing, learner.gamma, cells=cells), 0
    n_actions = source.n_actions
    data = random_transitions(spec.source, preset.source_samples, derive_seed(seed, spec.stream_name, "source-data"))
    regressor = fqi.make_regressor(
        {**learner.regressor_spec(), "seed": derive_seed(seed, spec.stream_name, "source-fqi")},
        data.state_dim,
    )
    q = fqi.fitted_q_iteration(data, n_actions, regressor, learner.gamma, learner.iterations)
    return q, len(data)


def _alignment_source(spec: ExperimentSpec, n: int, seed: int) -> Transitions:
    """The source's samples for a learned map: random-policy episodes unless the spec asks for its box."""
    side = spec.source
    if spec.mapping.source_data == "episodes":
        side = dataclasses.replace(
            side, data=dataclasses.replace(side.data, sampling="episodes", state_low=(), state_high=())
        )
    return random_transitions(side, n, derive_seed(seed, spec.stream_name, "alignment-source"))


def _learn_mapping(
    spec: ExperimentSpec,
    preset: Preset,
    seed: int,
    target_stream: Transitions,
) -> tuple[Any, dict | None, int, int]:
    """Phase II: the mapping (in each task's mapping coordinates), its record, and the
    source and target samples it used (the target's are the stream's head, reused later);
    built by its kind's entry of ``mappings.MAPPINGS``."""
    inputs = mappings.MappingInputs(
        settings=spec.mapping,
        source=description_of(spec.source),
        target=description_of(spec.target),
        n=preset.alignment_samples,
        source_samples=partial(_alignment_source, spec, seed=seed),
        target_stream=target_stream,
        rng=lambda: np.random.default_rng(derive_seed(seed, spec.stream_name, "alignment")),
    )
    return mappings.MAPPINGS[spec.mapping.kind](inputs)


def _random_return(spec: ExperimentSpec, preset: Preset, seed: int) -> float:
    """The uniformly random policy's mean return from the experiment's evaluation starts."""
    policy = random_policy(spec.target, derive_seed(seed, "random-policy"))
    returns, _ = target_returns(spec, preset, policy, derive_seed(seed, spec.stream_name, "evaluation"))
    return float(np.mean(returns))


def learn_source(
    spec: ExperimentSpec, preset: Preset, seed: int, shared: SourceArtifacts | None = None
) -> SourceArtifacts:
    """Phases I and II for one seed.

    ``shared``: the artefacts of an experiment that differs from this one only in its
    mapping and draws the same streams (``runner``): their source Q, target samples and
    random return are this one's, so only the mapping is learned (no phase is done twice).
    """
    timings = {"source_learning_s": 0.0, "target_sampling_s": 0.0}
    if shared is None:
        start = time.perf_counter()
        source_q, source_samples = _source_q(spec, preset, seed)
        timings["source_learning_s"] = time.perf_counter() - start

        start = time.perf_counter()
        stream_size = max(max(preset.target_budgets), preset.alignment_samples)
        target_stream = random_transitions(spec.target, stream_size, derive_seed(seed, spec.stream_name, "target-data"))
        timings["target_sampling_s"] = time.perf_counter() - start
    else:
        source_q, source_samples, target_stream = shared.source_q, shared.source_samples, shared.target_stream

    start = time.perf_counter()
    mapping, mapping_record, n_map_source, n_map_target = _learn_mapping(spec, preset, seed, target_stream)
    timings["mapping_s"] = time.perf_counter() - start

    start = time.perf_counter()
    random_return = _random_return(spec, preset, seed) if shared is None else shared.random_return
    timings["random_evaluation_s"] = time.perf_counter() - start
    return SourceArtifacts(
        source_q=source_q,
        mapping=mapping,
        target_stream=target_stream,
        random_return=random_return,
        mapping_target_samples=n_map_target,
        mapping_source_samples=n_map_source,
        source_samples=source_samples,
        timings=timings,
        mapping_record=mapping_record,
    )


# --- phase III ----------------------------------------------------------------


def _source_region(source: Side, description: TaskDescription, states: np.ndarray) -> np.ndarray:
    """The nearest state the source can be queried at: settable (the task's
    description says which; beyond the mountain car's track is not), and for a
    source learned from a uniform box, inside that box, where its Q was fitted."""
    states = description.clip_to_settable(states)
    if source.data.sampling == "uniform":
        states = np.clip(states, source.data.state_low, source.data.state_high)
    return states


@dataclasses.dataclass(frozen=True, eq=False)
class QueriedMapping:
    """A mapping whose chi_plus lands where the source is queried (``_source_region``), so a
    method chooses the source's action at the very state its simulator steps from."""

    inner: Any
    region: Callable[[np.ndarray], np.ndarray]

    def chi(self, source_states: np.ndarray) -> np.ndarray:
        return self.inner.chi(source_states)

    def chi_plus(self, target_states: np.ndarray) -> np.ndarray:
        return self.region(self.inner.chi_plus(target_states))


def _source_step(source: Side, description: TaskDescription, states: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """Algorithm 1's query of the source simulator, from the nearest state it can be queried at."""
    states = _source_region(source, description, states)
    return sampling.step_from(source.domain, source.task, states, actions, task_kwargs=source.task_kwargs)


def _target_step(target: Side, description: TaskDescription, states: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The real target's one step from ``states`` under the nearest discrete actions to ``values`` (oracles)."""
    values = np.asarray(values, dtype=np.float64).reshape(len(states), -1)
    if description.discrete:
        gaps = np.linalg.norm(values[:, None, :] - description.action_values[None], axis=2)
        return sampling.step_from(
            target.domain, target.task, states, np.argmin(gaps, axis=1), task_kwargs=target.task_kwargs
        )
    return sampling.step_values_from(target.domain, target.task, states, values, task_kwargs=target.task_kwargs)


def _policy_samples(spec: ExperimentSpec, seed: int, policy: Callable, n: int) -> Transitions:
    """n target transitions of ``policy`` from the target's own (random) starts, seeded per seed."""
    target = spec.target
    random = derive_seed(seed, spec.stream_name, "policy-data")
    description = description_of(target)
    if description.discrete and description.known_model is not None:
        # The same transitions, from the environment's resets and the known table's steps.
        return sampling.collect(
            target.domain,
            target.task,
            n,
            random,
            policy=policy,
            task_kwargs=target.task_kwargs,
            max_episode_steps=target.data.episode_steps,
        )
    env = suite.load(target.domain, target.task, task_kwargs={**target.task_kwargs, "random": random})
    actions = np.arange(description.n_actions) if description.discrete else suite.action_set(target.domain)
    index_policy = policy if description.discrete else _as_indices(policy, description.action_values)
    return sampling.policy_transitions(env, index_policy, n, actions, max_episode_steps=target.data.episode_steps)


def _nested_samples(
    gather: Callable[[Callable, int], Transitions], largest: int
) -> Callable[[Callable, int], Transitions]:
    """``policy_samples`` that collects once per policy and answers each budget with a head.

    The budgets of a run nest: the first call for a policy collects
    ``max(n, largest)`` transitions, later calls take the first n. That is what a
    fresh collection of n gives (episodes from the same seeded resets, in order,
    the last one cut at n: its final transition is marked ``last``; tested), for
    about half the stepping when budgets grow geometrically.
    """
    cache: dict[int, tuple[Callable, Transitions]] = {}

    def samples(policy: Callable, n: int) -> Transitions:
        entry = cache.get(id(policy))
        if entry is None or entry[0] is not policy or len(entry[1]) < n:
            entry = cache[id(policy)] = (policy, gather(policy, max(n, largest)))  # holding policy keeps its id
        head = entry[1].head(n)
        last = head.last.copy()
        last[-1] = True
        return dataclasses.replace(head, last=last)

    return samples


def _as_indices(policy: Callable, action_values: np.ndarray) -> Callable:
    """A policy over action values as one over the nearest discrete action's index."""

    def indices(states: np.ndarray) -> np.ndarray:
        values = np.asarray(policy(states), dtype=np.float64).reshape(len(states), -1)
        return np.argmin(np.linalg.norm(values[:, None] - action_values[None], axis=2), axis=1)

    return indices


def _target_reward(target: Side) -> Callable | None:
    """The target task's reward and end condition of a step, (s, a, s') -> (rewards, absorbing), or None.

    The description's ``transition_reward`` where the reward depends on the step
    (the grid world's bumps), else the task's ``batch_reward`` of the next state.
    """
    description = description_of(target)
    if description.transition_reward is not None and description.transition_absorbing is not None:
        step_reward, absorbing = description.transition_reward, description.transition_absorbing
    else:
        task = getattr(suite.load(target.domain, target.task, task_kwargs=target.task_kwargs), "task", None)
        if not hasattr(task, "batch_reward"):
            return None
        step_reward = lambda states, actions, next_states: task.batch_reward(next_states)  # noqa: E731
        absorbing = task.batch_absorbing

    def reward(states: np.ndarray, actions: np.ndarray, next_states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return (
            np.asarray(step_reward(states, actions, next_states), dtype=np.float64),
            np.asarray(absorbing(next_states), dtype=bool),
        )

    return reward


def _algorithm2_seed(spec: ExperimentSpec, seed: int) -> int:
    """Seeds the start states of Algorithm 2's rollouts, real and modelled: never the evaluation's."""
    return derive_seed(seed, spec.stream_name, "algorithm2-starts")


def _model_returns(
    spec: ExperimentSpec, preset: Preset, seed: int, reward: Callable | None
) -> tuple[Callable, Callable] | tuple[None, None]:
    """U_Mhat(pi) as hooks: ``model_return(model, policy, episodes=None)`` and
    ``model_returns(models, policy, episodes=None)`` (several models at once), or None
    where the task has no reward.

    The target task's own reward and end conditions (``_target_reward``) score the
    model's predicted states, from the start states of the real rollouts of U_M
    (``_algorithm2_seed``; ``episodes`` of them, default the evaluation protocol's),
    for the evaluation protocol's steps. A task with no such reward gets None:
    Algorithm 2 then cannot run there.
    """
    if reward is None:
        return None, None
    target = spec.target
    description = description_of(target)

    @cache
    def starts(episodes: int) -> np.ndarray:
        return sampling.start_states(
            target.domain, target.task, episodes, _algorithm2_seed(spec, seed), target.task_kwargs
        )

    settings = dict(
        reward=reward,
        action_values=description.action_values,
        steps=preset.evaluation_steps,
        snap=apprentice.state_snap(description),
    )

    def model_returns(models: list, policy: Callable, episodes: int | None = None) -> list[float]:
        return apprentice.model_returns(
            models, policy, starts=starts(episodes or preset.evaluation_episodes), **settings
        )

    return (lambda model, policy, episodes=None: model_returns([model], policy, episodes)[0]), model_returns


class Ledger:
    """The real-target transitions a method's problem hooks cost it, budget by budget.

    Data hooks charge what they hand out. A rollout of a policy (U_M) is run once
    per problem and its value kept, but charged at every budget that asks for it,
    since each budget's learner used it.
    """

    def __init__(self) -> None:
        self.count = 0
        self.rollouts = 0  # of ``count``, the transitions of policy rollouts (Algorithm 2's U_M)
        self._rollouts: dict[tuple[int, int | None], tuple[Callable, float, int]] = {}
        self._charged: set[tuple[int, int | None]] = set()

    def new_budget(self) -> None:
        self.count, self.rollouts, self._charged = 0, 0, set()

    def data(self, transitions: Transitions) -> Transitions:
        self.count += len(transitions)
        return transitions

    def charge(self, n: int) -> None:
        """Counts n transitions a method replays from an earlier budget's collection."""
        self.count += int(n)

    def rollout(
        self, policy: Callable, run: Callable[[Callable], tuple[np.ndarray, np.ndarray]], episodes: int | None = None
    ) -> float:
        key = (id(policy), episodes)
        entry = self._rollouts.get(key)
        if entry is None or entry[0] is not policy:
            returns, lengths = run(policy)
            entry = self._rollouts[key] = (policy, float(np.mean(returns)), int(np.sum(lengths)))
        if key not in self._charged:
            self._charged.add(key)
            self.count += entry[2]
            self.rollouts += entry[2]
        return entry[1]


def _reset_samples(
    spec: ExperimentSpec, seed: int, largest: int, reward: Callable | None
) -> Callable[[int], Transitions]:
    """The reset protocol's data: heads of one stream of one-step transitions from the reset box."""
    description = description_of(spec.target)
    cache: list[Transitions] = []

    def samples(n: int) -> Transitions:
        if not cache or len(cache[0]) < n:
            rng = np.random.default_rng(derive_seed(seed, spec.stream_name, "reset-data"))
            size = max(n, largest)
            states = description.reset_states(size, rng)
            cache[:] = [one_step(spec.target, states, rng.integers(description.n_actions, size=size), reward)]
        return cache[0].head(n)

    return samples


def _episode_samples(spec: ExperimentSpec, seed: int) -> Callable[[Callable | None, int, int], Transitions]:
    """The online protocol's data: whole episodes from the target's own starts, seeded per round."""
    target = spec.target

    def samples(policy: Callable | None, n: int, round_: int) -> Transitions:
        return sampling.collect(
            target.domain,
            target.task,
            n,
            derive_seed(seed, spec.stream_name, "online-data", str(round_)),
            policy=policy,
            task_kwargs=target.task_kwargs,
            max_episode_steps=target.data.episode_steps,
        )

    return samples


def transfer_problem(
    spec: ExperimentSpec,
    preset: Preset,
    artifacts: SourceArtifacts,
    seed: int,
    ledger: Ledger | None = None,
    placebo: bool = False,
    uses_source: bool = True,
) -> "method.TransferProblem":
    """The problem a transfer method learns (see ``tatl_mj.transfer.method``), with its hooks.

    Every hook that touches the real target charges ``ledger`` (a fresh one if None).
    ``placebo`` puts an untrained source Q of the trained one's shape in
    place of the trained one (``tatl_mj.transfer.placebo``), drawn from this seed.
    Without ``uses_source`` the source Q, mapping and source simulator are withheld
    (``method.Withheld``): the method's record then cannot depend on them.
    """
    ledger = Ledger() if ledger is None else ledger
    source, target = description_of(spec.source), description_of(spec.target)
    rollout_seed = _algorithm2_seed(spec, seed)

    def target_return(policy: Callable, episodes: int | None = None) -> float:
        protocol = preset if episodes is None else dataclasses.replace(preset, evaluation_episodes=episodes)
        return ledger.rollout(policy, lambda p: target_returns(spec, protocol, p, rollout_seed), episodes)

    reward = _target_reward(spec.target)  # loads the task once: every hook below shares it
    policy_samples = _nested_samples(partial(_policy_samples, spec, seed), max(preset.target_budgets))
    reset_samples = _reset_samples(spec, seed, max(preset.target_budgets), reward)
    episode_samples = _episode_samples(spec, seed)
    model_return, model_returns = _model_returns(spec, preset, seed, reward)
    source_q = artifacts.source_q
    if placebo:
        source_q = placebo_q(source_q, derive_seed(seed, spec.stream_name, "placebo"))
    source_parts: dict[str, Any] = dict(
        source_q=source_q,
        mapping=QueriedMapping(artifacts.mapping, partial(_source_region, spec.source, source)),
        source_step=partial(_source_step, spec.source, source),
    )
    if not uses_source:
        source_parts = {name: method.Withheld(name) for name in source_parts}
    return method.TransferProblem(
        **source_parts,
        source=source,
        target=target,
        seed=derive_seed(seed, spec.stream_name, "target-learning"),
        target_return=target_return,
        model_return=model_return,
        model_returns=model_returns,
        target_step=partial(_target_step, spec.target, target),
        policy_samples=lambda policy, n: ledger.data(policy_samples(policy, n)),
        target_reward=reward,
        reset_samples=lambda n: ledger.data(reset_samples(n)),
        episode_samples=lambda policy, n, round_: ledger.data(episode_samples(policy, n, round_)),
        charge=ledger.charge,
    )


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
    curve = _evaluated_curve(spec, preset, problem.target, points, policies, eval_seed)
    for budget in preset.target_budgets[len(curve) :]:
        curve.append({**curve[-1], "samples": int(budget), "samples_used": 0, "learn_s": 0.0, "evaluate_s": 0.0})
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
    stream = used if hooks.data in STREAM_DATA else 0
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
) -> list[dict]:
    """The curve's points with their evaluations: every budget's policy in one lockstep batch.

    A policy learned at several budgets (the same object) is evaluated once: its
    episodes are the same at each, from the same starts and noise.
    """
    distinct = list({id(policy): policy for policy in policies}.values())
    start = time.perf_counter()
    evaluated = evaluate_curve(spec, preset, distinct, eval_seed, bool(target.steadiness))
    evaluate_s = time.perf_counter() - start
    steps = sum(int(n.sum()) for _, n, _ in evaluated)
    of = {id(policy): result for policy, result in zip(distinct, evaluated)}
    curve: list[dict] = []
    timed: set[int] = set()
    for point, policy in zip(points, policies):
        returns, lengths, calls = of[id(policy)]
        share = evaluate_s * int(lengths.sum()) / max(steps, 1) if id(policy) not in timed else 0.0
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
                "evaluate_s": share,
            }
        )
    return curve
