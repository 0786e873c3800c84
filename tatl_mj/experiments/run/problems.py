"""The transfer problem a method learns (``transfer_problem``; see
``tatl_mj.transfer.method``) and its hooks into the real tasks, with the :class:`Ledger`
that charges the method every real-target transition they hand out or roll out.

The hooks: the source simulator queried where the source can be (``QueriedMapping``),
the target's own data protocols (policy, reset and online samples), its reward, and
Algorithm 2's real and modelled returns U_M and U_Mhat. Algorithm 2's rollouts start
from their own start states, never the evaluation's.
"""

from __future__ import annotations

import dataclasses
from functools import cache, partial
from typing import Any, Callable

import numpy as np

from tatl_mj import sampling, suite
from tatl_mj.description import TaskDescription
from tatl_mj.experiments.run.determinism import derive_seed
from tatl_mj.experiments.run.evaluation import target_returns
from tatl_mj.experiments.run.sides import description_of, one_step, target_reward
from tatl_mj.experiments.run.source_unit import SourceArtifacts
from tatl_mj.experiments.spec import ExperimentSpec, Preset, Side
from tatl_mj.transfer import apprentice, method
from tatl_mj.transfer.placebo import placebo_q
from tatl_mj.transitions import Transitions


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


def learning_seed(spec: ExperimentSpec, seed: int) -> int:
    """The seed a method's ``learn`` draws from (``TransferProblem.seed``): the same for every method."""
    return derive_seed(seed, spec.stream_name, "target-learning")


def _algorithm2_seed(spec: ExperimentSpec, seed: int) -> int:
    """Seeds the start states of Algorithm 2's rollouts, real and modelled: never the evaluation's."""
    return derive_seed(seed, spec.stream_name, "algorithm2-starts")


def _model_returns(
    spec: ExperimentSpec, preset: Preset, seed: int, reward: Callable | None
) -> tuple[Callable, Callable] | tuple[None, None]:
    """U_Mhat(pi) as hooks: ``model_return(model, policy, episodes=None)`` and
    ``model_returns(models, policy, episodes=None)`` (several models at once), or None
    where the task has no reward.

    The target task's own reward and end conditions (``target_reward``) score the
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

    reward = target_reward(spec.target)  # loads the task once: every hook below shares it
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
        seed=learning_seed(spec, seed),
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
