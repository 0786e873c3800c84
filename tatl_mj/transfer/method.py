"""The plug-in interface: what a transfer method gets, and what it must return.

A method is an object with a ``name`` and ``learn(problem, target_samples) -> Policy``
(the :class:`TransferMethod` protocol), in the scikit-learn style: its settings go
to its constructor (``TATL(zeta=0.1, apprentice={"kind": "linear"})``), the data to
``learn``. :class:`TransferProblem` holds the problem only: the source's Q-function
and simulator step, the inter-task mapping, both tasks' descriptions, and
evaluation hooks any method may call (so Algorithm 2's utility gap is available to
every method, built-in or plug-in). ``target_samples`` are the target transitions
the method is allowed to see (its budget); a method must not step the target any
other way (the hooks evaluate policies; they never hand out transitions).

The built-ins are :class:`TATL` (the paper's Algorithms 1 and 2), :class:`UMATL`
and :class:`RL`; ``tatl_mj.transfer.registry`` names every built-in. To compare your
own method, pass an instance of it next to these to the experiment runner.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import warnings
from typing import Any, Callable, Protocol, runtime_checkable

import numpy as np

from tatl_mj.description import TaskDescription
from tatl_mj.transfer.alignment import Mapping
from tatl_mj.transfer.apprentice import Apprentice, fit_apprentice, learn_apprentice
from tatl_mj.transfer.baselines import MappedQ
from tatl_mj.transfer.features import Features, make_features
from tatl_mj.transfer.fqi import REGRESSOR_KINDS, QFunction, fitted_q_iteration, make_regressor
from tatl_mj.transfer.placebo import SOURCES
from tatl_mj.transfer.tatl import DiscreteTATLPolicy, SourceStep, TATLPolicy
from tatl_mj.transitions import Transitions
from tatl_mj.validation import choice, integer, number

Policy = Callable[[np.ndarray], np.ndarray]
"""Batched target policy: (N, dT) states -> (N, mT) action values, or (N,) indices for a discrete target."""

Model = Any
"""A target model standing in for the simulator: ``predict(states, action_values) -> next_states``."""


@dataclasses.dataclass(frozen=True, eq=False)
class TransferProblem:
    """Everything a transfer method may use besides the target samples.

    Attributes:
      source_q: Q_S learned on the source (Phase I).
      mapping: chi / chi_plus between the state spaces (Phase II).
      source_step: one batched source-simulator step, (N, dS), (N,) indices -> (N, dS).
      source, target: the two tasks' descriptions (``tatl_mj.suite.describe``): state
        names and periodic coordinates, action values (row i of the source's
        corresponds to row i of the target's, Assumption 1), actuator limits,
        control steps, a known model where there is one.
      seed: seeds every random choice a method makes.
      target_return: U_M(pi), the mean return of a policy on the real target under
        the experiment's evaluation protocol (no target samples are handed out).
      model_return: U_Mhat(pi), the same policy's mean return when ``model`` stands
        in for the target (the target task's reward and end conditions applied to
        the model's predicted states); None where the task has no such reward.
      target_step: the real target simulator's one step, (N, dT) states, (N, mT)
        action values -> (N, dT); for oracle ablations only (it is not a sample
        budget a fair method may use).
      policy_samples: ``policy_samples(policy, n)`` -> n target transitions from
        episodes of ``policy`` from the target's start distribution: the paper's
        protocol for the apprentice's data ("execute pi*(S) in the target from
        random starts"), for a method that spends its budget that way instead of
        on the shared random-policy stream.
      target_reward: the target task's own reward and end condition of a step,
        ``(states, action_indices, next_states) -> (rewards (N,), absorbing (N,))``,
        for a learner that scores a model's transitions (``apprentice-fqi``).
      reset_samples: ``reset_samples(n)`` -> n one-step target transitions from
        states spread over the target's reset box with random actions (the
        ``reset`` data protocol; privileged: a simulator reset a robot lacks).
      episode_samples: ``episode_samples(policy, n, round)`` -> n transitions of
        whole episodes of an index ``policy`` (None: uniformly random actions)
        from the target's own start states, the resets seeded by ``round``
        (the ``online`` data protocol; no resets to chosen states).
      charge: ``charge(n)`` counts n real-target transitions against the method that
        it learns from again without asking a hook for them: an earlier budget's
        collection that it replays, because its own run would have collected the
        very same data (None: nothing may be replayed).

    Every real-target transition a hook hands out or rolls out is counted
    against the method (``target_transitions`` in the records).
    """

    source_q: QFunction
    mapping: Mapping
    source_step: SourceStep
    source: TaskDescription
    target: TaskDescription
    seed: int = 0
    target_return: Callable[[Policy], float] | None = None
    model_return: Callable[[Model, Policy], float] | None = None
    target_step: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
    policy_samples: Callable[[Policy, int], Transitions] | None = None
    target_reward: Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None
    reset_samples: Callable[[int], Transitions] | None = None
    episode_samples: Callable[[Callable | None, int, int], Transitions] | None = None
    charge: Callable[[int], None] | None = None
    # Rounds a method keeps to replay at a later budget of the same run (see
    # TargetFQI._online); not part of the problem's identity.
    replays: dict = dataclasses.field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        if self.source.n_actions != self.target.n_actions:
            raise ValueError(
                f"the source has {self.source.n_actions} actions and the target {self.target.n_actions}; "
                "Assumption 1 pairs them one to one"
            )

    @property
    def n_actions(self) -> int:
        return self.target.n_actions

    def projected_source_policy(self) -> Policy:
        """pi_hat(s_T) = pi*_S(chi_plus(s_T)), carried to the target action of the same index.

        The same object on every call, so that hooks may cache by policy (the
        paper-protocol data of ``policy_samples`` is collected once per problem).
        """
        cached = self.__dict__.get("_projected_source_policy")
        if cached is not None:
            return cached
        source_q, mapping, target = self.source_q, self.mapping, self.target

        def policy(states: np.ndarray) -> np.ndarray:
            index = source_q.greedy(mapping.chi_plus(states))
            return index if target.discrete else target.action_values[index]

        object.__setattr__(self, "_projected_source_policy", policy)  # frozen: a cache, not a field
        return policy

    @property
    def has_utility_gap(self) -> bool:
        """Whether Algorithm 2's utility gap can be computed (both hooks given)."""
        return self.target_return is not None and self.model_return is not None

    def utility_gap(self, model: Model, kind: str = "absolute") -> float:
        """Algorithm 2's gap between U_M(pi) and U_Mhat(pi) for the projected source policy.

        ``"absolute"`` (the paper's): U_M - U_Mhat, compared one-sided with zeta;
        ``"relative"``: |U_M - U_Mhat| / |U_M|. Both come from the same start
        states (the problem's hooks say which), and U_M's real-target rollouts are
        counted against the method that asks. A model whose rollout diverges is as
        far from the target as can be (1e300).
        """
        if not self.has_utility_gap:
            raise ValueError("this problem has no target_return/model_return hooks: no utility gap")
        assert self.target_return is not None and self.model_return is not None
        u_true = float(self.target_return(self.projected_source_policy()))
        u_hat = self.model_return(model, self.projected_source_policy())
        if not math.isfinite(u_hat):
            return 1e300
        if kind == "relative":
            return abs(u_true - u_hat) / max(abs(u_true), 1e-9)
        return u_true - u_hat


@runtime_checkable
class TransferMethod(Protocol):
    """A transfer method that the experiments can compare: a ``name`` and ``learn``.

    The experiments also read these optional attributes, with these defaults
    (:func:`contract` reads them, the one place that does):

    - ``check(source, target)``: raises ValueError (one line) where the method
      cannot run on these tasks' descriptions; called when a spec is loaded and
      before a run starts (default: none);
    - ``uses_samples``: False for a reference that learns nothing from the target
      (learned and evaluated once, counts 0; default True);
    - ``data``: where its transitions come from, ``"shared"`` (the first n of
      the shared random-policy stream, counted as used) or its own (anything
      else: only what the problem's hooks hand out is counted; default "shared");
    - ``source``: ``"trained"`` or ``"placebo"`` (the problem then holds an
      untrained source Q of the trained one's shape; default "trained");
    - on the returned policy, ``samples_used``: how many of the n shared samples
      it kept (Algorithm 2 may stop early; default n).
    """

    name: str

    def learn(self, problem: TransferProblem, target_samples: Transitions) -> Policy: ...


@dataclasses.dataclass(frozen=True)
class Contract:
    """What the experiments read of a method beyond ``name`` and ``learn`` (see
    :class:`TransferMethod`), with its defaults filled in."""

    uses_samples: bool = True
    data: str = "shared"
    source: str = "trained"
    check: Callable[[TaskDescription, TaskDescription], None] | None = None


def contract(method: Any) -> Contract:
    """``method``'s optional hooks and attributes, defaults where it has none."""
    return Contract(
        uses_samples=bool(getattr(method, "uses_samples", True)),
        data=str(getattr(method, "data", "shared")),
        source=str(getattr(method, "source", "trained")),
        check=getattr(method, "check", None),
    )


def samples_used(policy: Any, budget: int) -> int:
    """How many of the ``budget`` shared samples ``policy`` kept (its ``samples_used``, else all)."""
    reported = getattr(policy, "samples_used", None)
    return int(budget) if reported is None else int(reported)


def check_features(owner: str, field: str, spec: Any, state_dim: int | None = None) -> None:
    """A basis spec's keys and kind are valid (and, given ``state_dim``, its sizes)."""
    try:
        make_features(spec, state_dim if state_dim is not None else _probe_dim(spec))
    except ValueError as error:
        raise ValueError(f"{owner}.{field}: {error}") from None


def _probe_dim(spec: Any) -> int:
    """A state size that a basis spec can be built with, to check its keys before the task is known."""
    if isinstance(spec, dict):
        for key in ("low", "periodic"):
            if isinstance(spec.get(key), (list, tuple)):
                return len(spec[key])
        if spec.get("kind") == "onehot":
            return 2
    return 1


@dataclasses.dataclass(frozen=True, eq=False)
class GreedyPolicy:
    """The greedy policy of a target Q-function, as action values (or indices if discrete)."""

    q: QFunction
    target_actions: np.ndarray
    discrete: bool = False
    samples_used: int | None = None  # shared-stream samples it learned from (None: the whole budget)

    def __call__(self, target_states: np.ndarray) -> np.ndarray:
        idx = self.q.greedy(target_states)
        return (
            idx
            if self.discrete
            else np.asarray(self.target_actions, dtype=np.float64).reshape(len(self.target_actions), -1)[idx]
        )


@dataclasses.dataclass(frozen=True)
class TATL:
    """Target Apprentice TL, the paper's rule: apprentice by Algorithm 2, policy by Algorithm 1.

    Attributes:
      apprentice: basis phi of the apprentice s' = W phi(s) + B a (a features spec,
        ``tatl_mj.transfer.features.make_features``).
      ridge: ridge of the apprentice's least squares (0: plain least squares).
      zeta: Algorithm 2's threshold; the apprentice grows by ``batch`` samples until
        the utility gap is <= zeta. None fits it on every sample.
      gap: ``"absolute"``, the paper's one-sided U_M - U_Mhat <= zeta (in return
        units), or ``"relative"``, |U_M - U_Mhat| / |U_M| <= zeta.
      batch: Algorithm 2's sample increment (None: all samples at once).
      actions: ``"discrete"``: the action is snapped to the target's discrete
        action set, the one the FQI baselines choose from, so every method is
        compared within the same actions; ``"continuous"``: any value within the
        actuator limits (a labelled variant).
      adaptive_actions: an explicit admissible set A_ad (values of a one-dimensional
        actuator) to snap to instead.
      source: ``"trained"``, the source Q of Phase I, or ``"placebo"``, an untrained
        one of its shape (``tatl_mj.transfer.placebo``): the placebo-source ablation.
    """

    apprentice: dict = dataclasses.field(default_factory=lambda: {"kind": "linear"})
    ridge: float = 0.0
    zeta: float | None = 0.1
    gap: str = "absolute"
    batch: int | None = None
    actions: str = "discrete"
    adaptive_actions: tuple[float, ...] = ()
    source: str = "trained"
    name: str = "ta-tl"

    GAPS = ("absolute", "relative")
    ACTION_SETS = ("discrete", "continuous")

    def __post_init__(self) -> None:
        owner = type(self).__name__
        check_features(owner, "apprentice", self.apprentice)
        choice(owner, "gap", self.gap, self.GAPS)
        choice(owner, "actions", self.actions, self.ACTION_SETS)
        choice(owner, "source", self.source, SOURCES)
        number(owner, "ridge", self.ridge, 0.0)
        if self.zeta is not None:
            number(owner, "zeta", self.zeta, 0.0, low_open=True)
        if self.batch is not None:
            integer(owner, "batch", self.batch, 1)
        for i, value in enumerate(self.adaptive_actions):
            number(owner, f"adaptive_actions[{i}]", value)

    def check(self, source: TaskDescription, target: TaskDescription) -> None:
        """Settings that need the tasks' descriptions (basis size, actuator)."""
        check_features(type(self).__name__, "apprentice", self.apprentice, target.state_dim)
        if self.adaptive_actions and target.discrete:
            raise ValueError(f"{type(self).__name__}.adaptive_actions apply to a continuous actuator only")

    def features(self, target: TaskDescription) -> Features:
        return make_features(self.apprentice, target.state_dim)

    def fit_apprentice(self, problem: TransferProblem, target_samples: Transitions) -> tuple[Apprentice, int]:
        """The apprentice on ``target_samples``: by Algorithm 2 where the problem can evaluate
        the utility gap and ``zeta`` is set, else on every sample. Returns it and the samples used."""
        target = problem.target
        actions = target.action_values
        periodic = target.periodic if any(target.periodic) else None
        if self.zeta is None or not problem.has_utility_gap:
            apprentice = fit_apprentice(
                target_samples.states,
                actions[target_samples.actions],
                target_samples.next_states,
                self.features(target),
                self.ridge,
                periodic=periodic,
            )
            return apprentice, len(target_samples)
        return learn_apprentice(
            target_samples,
            actions,
            self.features(target),
            functools.partial(problem.utility_gap, kind=self.gap),
            self.zeta,
            self.batch or len(target_samples),
            self.ridge,
            periodic=periodic,
        )

    def learn(self, problem: TransferProblem, target_samples: Transitions) -> Policy:
        apprentice, used = self.fit_apprentice(problem, target_samples)
        target = problem.target
        common = dict(
            source_q=problem.source_q,
            mapping=problem.mapping,
            source_step=problem.source_step,
            apprentice=apprentice,
            source_actions=problem.source.action_values,
            target_actions=target.action_values,
            target_low=target.action_low,
            target_high=target.action_high,
            adaptive_actions=self.admissible_actions(target),
            samples_used=used,
        )
        return DiscreteTATLPolicy(**common) if target.discrete else TATLPolicy(**common)

    def admissible_actions(self, target: TaskDescription) -> np.ndarray | None:
        """The set the action is snapped to: A_ad if given, the target's discrete
        action set for ``actions = "discrete"``, else None (clipped only)."""
        if self.adaptive_actions:
            return np.asarray(self.adaptive_actions, dtype=np.float64).reshape(-1, 1)
        if self.actions == "discrete" and not target.discrete:
            return np.asarray(target.action_values, dtype=np.float64)
        return None


@dataclasses.dataclass(frozen=True)
class ProjectedSource:
    """The mapped source policy pi*_S(chi_plus(s_T)) without adaptation: a reference, no target samples."""

    name: str = "projected-source"
    uses_samples = False  # evaluated once, whatever the budget

    def learn(self, problem: TransferProblem, target_samples: Transitions) -> Policy:
        return problem.projected_source_policy()


DATA_PROTOCOLS = ("shared", "reset", "online")
"""Where a target learner's transitions come from (``TargetFQI.data``)."""


@dataclasses.dataclass(frozen=True)
class TargetFQI:
    """Target Fitted Q-Iteration, the learner of :class:`UMATL`, :class:`RL` and their kin.

    Attributes:
      features: basis of the linear regressor (a features spec, default linear);
        refused for extra-trees, which split raw states.
      regressor: ``"linear"`` or ``"extra_trees"``.
      ridge: the linear regressor's ridge (default 1e-6); refused for extra-trees.
      n_estimators: extra-trees' tree count (default 50); refused for linear.
      gamma, iterations: FQI's discount and iteration count.
      data: where its n target transitions come from (n: the budget):
        ``"shared"``, the first n of the random-policy stream every method shares;
        ``"reset"``, n one-step transitions from states spread over the target's
        reset box (privileged: a simulator reset that a robot lacks);
        ``"online"``, epsilon-greedy episodes from the task's own start states,
        refitting as the data double (random actions for the first
        ``online_batch``), no resets to chosen states.
      epsilon: the online protocol's exploration rate.
      online_batch: the online protocol's first, random-policy collection.
      source: ``"trained"`` or ``"placebo"`` (see :class:`TATL`); only for learners
        that use the mapped source Q (UMA-TL and its kin).
    """

    features: dict | None = None
    regressor: str = "linear"
    ridge: float | None = None
    n_estimators: int | None = None
    gamma: float = 0.95
    iterations: int = 20
    data: str = "shared"
    epsilon: float = 0.1
    online_batch: int = 100
    source: str = "trained"
    name: str = "target-fqi"
    source_use = "none"  # how the mapped source Q enters: "none", "initial" (Q_0) or "prior" (every fit)

    def __post_init__(self) -> None:
        owner = type(self).__name__
        choice(owner, "regressor", self.regressor, REGRESSOR_KINDS)
        for field in ("ridge", "features"):
            if getattr(self, field) is not None and self.regressor != "linear":
                raise ValueError(f"{owner}.{field} applies to regressor 'linear' only, not {self.regressor!r}")
        if self.n_estimators is not None:
            if self.regressor != "extra_trees":
                raise ValueError(f"{owner}.n_estimators applies to regressor 'extra_trees' only")
            integer(owner, "n_estimators", self.n_estimators, 1)
        if self.ridge is not None:
            number(owner, "ridge", self.ridge, 0.0)
        if self.regressor == "linear":
            check_features(owner, "features", self.linear_features)
        number(owner, "gamma", self.gamma, 0.0, 1.0, high_open=True)
        integer(owner, "iterations", self.iterations, 1)
        choice(owner, "data", self.data, DATA_PROTOCOLS)
        number(owner, "epsilon", self.epsilon, 0.0, 1.0)
        integer(owner, "online_batch", self.online_batch, 1)
        choice(owner, "source", self.source, SOURCES)
        if self.source == "placebo" and self.source_use == "none":
            raise ValueError(f"{owner}.source = 'placebo' needs a learner that uses the source Q; {owner} uses none")

    @property
    def linear_features(self) -> dict:
        return {"kind": "linear"} if self.features is None else self.features

    def check(self, source: TaskDescription, target: TaskDescription) -> None:
        if self.regressor == "linear":
            check_features(type(self).__name__, "features", self.linear_features, target.state_dim)
        if self.data == "reset" and target.reset_low is None and not (target.discrete and target.known_model):
            raise ValueError(
                f"{type(self).__name__}.data = 'reset' needs a reset box; {target.domain}/{target.task} declares none"
            )

    def regressor_spec(self) -> dict:
        spec: dict = {"kind": self.regressor, "features": self.linear_features}
        if self.regressor == "linear":
            spec["ridge"] = 1e-6 if self.ridge is None else self.ridge
        elif self.n_estimators is not None:
            spec["n_estimators"] = self.n_estimators
        return spec

    def fqi(self, problem: TransferProblem, data: Transitions, rng: np.random.Generator) -> QFunction:
        """FQI on ``data``, with the mapped source Q as this learner's ``source_use`` says."""
        regressor = make_regressor(self.regressor_spec(), data.state_dim)
        mapped = MappedQ(problem.source_q, problem.mapping) if self.source_use != "none" else None
        return fitted_q_iteration(
            data,
            problem.n_actions,
            regressor,
            self.gamma,
            self.iterations,
            initial_q=mapped if self.source_use == "initial" else None,
            prior_q=mapped if self.source_use == "prior" else None,
            rng=rng,
        )

    def fit(self, problem: TransferProblem, data: Transitions, rng: np.random.Generator) -> QFunction:
        """The Q-function this learner makes of its target transitions (a subclass's own step)."""
        return self.fqi(problem, data, rng)

    def learn(self, problem: TransferProblem, target_samples: Transitions) -> Policy:
        rng = np.random.default_rng(problem.seed)
        n = len(target_samples)
        if self.data == "shared":
            q = self.fit(problem, target_samples, rng)
        elif self.data == "reset":
            if problem.reset_samples is None:
                raise ValueError(f"{type(self).__name__}(data='reset') needs the problem's reset_samples")
            q = self.fit(problem, problem.reset_samples(n), rng)
        else:
            q = self._online(problem, n, rng)
        used = n if self.data == "shared" else 0  # the others draw their own, counted by the hooks
        return GreedyPolicy(q, problem.target.action_values, problem.target.discrete, samples_used=used)

    def _online(self, problem: TransferProblem, n: int, rng: np.random.Generator) -> QFunction:
        """Epsilon-greedy FQI: random episodes first, then the data doubled by the current greedy policy.

        A budget's rounds up to where its collection sizes part from a smaller
        budget's are that budget's very rounds (each round's data, fit and draws
        follow from the sizes so far and the seed alone), so where the problem can
        charge replays, each round is kept with the problem and replayed: its data
        charged again, its fit and the generator's state after it restored.
        """
        if problem.episode_samples is None:
            raise ValueError(f"{type(self).__name__}(data='online') needs the problem's episode_samples")
        memo = problem.replays if problem.charge is not None else None
        sizes: tuple[int, ...] = ()
        data: Transitions | None = None
        q: QFunction | None = None
        round_ = 0
        while True:
            size = min(n, self.online_batch) if data is None else min(len(data), n - len(data))
            sizes += (size,)
            entry = memo.get((id(self), sizes)) if memo is not None else None
            if entry is not None and entry[0] is self:
                _, data, q, state, collected = entry
                rng.bit_generator.state = state
                problem.charge(collected)  # type: ignore[misc]
            else:
                with warnings.catch_warnings(record=True) as caught:
                    policy = None if q is None else _epsilon_greedy(q, self.epsilon, rng)
                    more = problem.episode_samples(policy, size, round_)
                    data = more if data is None else Transitions.concatenate([data, more])
                    q = self.fit(problem, data, rng)
                for warning in caught:
                    warnings.warn_explicit(warning.message, warning.category, warning.filename, warning.lineno)
                if memo is not None and not caught:  # a replay would not repeat a warning
                    memo[(id(self), sizes)] = (self, data, q, rng.bit_generator.state, len(more))
            if len(data) >= n:
                return q
            round_ += 1


def _epsilon_greedy(q: QFunction, epsilon: float, rng: np.random.Generator) -> Callable[[np.ndarray], np.ndarray]:
    """Index policy: greedy in ``q``, a uniformly random action with probability ``epsilon``."""

    def policy(states: np.ndarray) -> np.ndarray:
        greedy = q.greedy(states)
        explore = rng.random(len(greedy)) < epsilon
        return np.where(explore, rng.integers(q.n_actions, size=len(greedy)), greedy)

    return policy


@dataclasses.dataclass(frozen=True)
class UMATL(TargetFQI):
    """UMA-TL: target FQI initialised with the mapped source Q (Ammar et al. 2015).

    The mapped source Q is only the first iteration's bootstrap: after enough
    iterations its influence is gone (see :class:`UMATLPrior`)."""

    name: str = "uma-tl"
    source_use = "initial"


@dataclasses.dataclass(frozen=True)
class UMATLPrior(TargetFQI):
    """UMA-TL whose mapped source Q stays in every fit: FQI on the residual from it,
    so a misleading source can show as negative transfer (not the paper's baseline)."""

    name: str = "uma-tl-prior"
    source_use = "prior"


@dataclasses.dataclass(frozen=True)
class RL(TargetFQI):
    """No transfer: target FQI from scratch."""

    name: str = "rl"


__all__ = [
    "DATA_PROTOCOLS",
    "GreedyPolicy",
    "Model",
    "Policy",
    "ProjectedSource",
    "RL",
    "TATL",
    "TargetFQI",
    "TransferMethod",
    "TransferProblem",
    "UMATL",
    "UMATLPrior",
    "Contract",
    "check_features",
    "contract",
    "samples_used",
]
