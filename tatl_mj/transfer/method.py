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
from typing import Any, Callable, Protocol, runtime_checkable

import numpy as np

from tatl_mj.description import TaskDescription
from tatl_mj.transfer.alignment import Mapping
from tatl_mj.transfer.apprentice import Apprentice, fit_apprentice, learn_apprentice
from tatl_mj.transfer.baselines import rl, uma_tl
from tatl_mj.transfer.features import Features, make_features
from tatl_mj.transfer.fqi import REGRESSOR_KINDS, QFunction, make_regressor
from tatl_mj.transfer.tatl import DiscreteTATLPolicy, SourceStep, TATLPolicy
from tatl_mj.transitions import Transitions

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

    @functools.cached_property
    def _projected_utility(self) -> float:
        assert self.target_return is not None
        return float(self.target_return(self.projected_source_policy()))

    def utility_gap(self, model: Model) -> float:
        """Algorithm 2's relative gap |U_M(pi) - U_Mhat(pi)| / |U_M(pi)| of the projected source policy.

        U_M is computed once per problem; a model whose rollout diverges is as far
        from the target as can be (1e300).
        """
        if not self.has_utility_gap:
            raise ValueError("this problem has no target_return/model_return hooks: no utility gap")
        assert self.model_return is not None
        u_true = self._projected_utility
        u_hat = self.model_return(model, self.projected_source_policy())
        if not math.isfinite(u_hat):
            return 1e300
        return abs(u_true - u_hat) / max(abs(u_true), 1e-9)


@runtime_checkable
class TransferMethod(Protocol):
    """A transfer method that the experiments can compare."""

    name: str

    def learn(self, problem: TransferProblem, target_samples: Transitions) -> Policy: ...


def _check_choice(owner: str, field: str, value: Any, valid: tuple) -> None:
    if value not in valid:
        raise ValueError(f"{owner}.{field} is {value!r}; valid choices: {list(valid)}")


def _check_number(
    owner: str,
    field: str,
    value: Any,
    low: float,
    high: float = math.inf,
    low_open: bool = False,
    high_open: bool = False,
    integer: bool = False,
) -> None:
    kind = "an integer" if integer else "a number"
    ok_type = isinstance(value, (int, np.integer)) if integer else isinstance(value, (int, float, np.number))
    if isinstance(value, bool) or not ok_type or not math.isfinite(value):
        raise ValueError(f"{owner}.{field} must be {kind}, got {value!r}")
    if value < low or (low_open and value == low) or value > high or (high_open and value == high):
        interval = f"{'(' if low_open else '['}{low}, {high}{')' if high_open else ']'}"
        raise ValueError(f"{owner}.{field} must be in {interval}, got {value!r}")


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
      zeta: Algorithm 2's threshold on the relative utility gap; the apprentice grows
        by ``batch`` samples until the gap is <= zeta. None fits it on every sample.
      batch: Algorithm 2's sample increment (None: all samples at once).
      adaptive_actions: the admissible set A_ad (values of a one-dimensional
        actuator); empty: any value within the actuator limits.
    """

    apprentice: dict = dataclasses.field(default_factory=lambda: {"kind": "linear"})
    ridge: float = 0.0
    zeta: float | None = 0.1
    batch: int | None = None
    adaptive_actions: tuple[float, ...] = ()
    name: str = "ta-tl"

    def __post_init__(self) -> None:
        owner = type(self).__name__
        check_features(owner, "apprentice", self.apprentice)
        _check_number(owner, "ridge", self.ridge, 0.0)
        if self.zeta is not None:
            _check_number(owner, "zeta", self.zeta, 0.0, low_open=True)
        if self.batch is not None:
            _check_number(owner, "batch", self.batch, 1, integer=True)
        for i, value in enumerate(self.adaptive_actions):
            _check_number(owner, f"adaptive_actions[{i}]", value, -math.inf)

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
            problem.utility_gap,
            self.zeta,
            self.batch or len(target_samples),
            self.ridge,
            periodic=periodic,
        )

    def learn(self, problem: TransferProblem, target_samples: Transitions) -> Policy:
        apprentice, used = self.fit_apprentice(problem, target_samples)
        target = problem.target
        adaptive = np.asarray(self.adaptive_actions, dtype=np.float64).reshape(-1, 1) if self.adaptive_actions else None
        common = dict(
            source_q=problem.source_q,
            mapping=problem.mapping,
            source_step=problem.source_step,
            apprentice=apprentice,
            source_actions=problem.source.action_values,
            target_actions=target.action_values,
            target_low=target.action_low,
            target_high=target.action_high,
            adaptive_actions=adaptive,
            samples_used=used,
        )
        return DiscreteTATLPolicy(**common) if target.discrete else TATLPolicy(**common)


@dataclasses.dataclass(frozen=True)
class ProjectedSource:
    """The mapped source policy pi*_S(chi_plus(s_T)) without adaptation: a reference, no target samples."""

    name: str = "projected-source"
    uses_samples = False  # evaluated once, whatever the budget

    def learn(self, problem: TransferProblem, target_samples: Transitions) -> Policy:
        return problem.projected_source_policy()


@dataclasses.dataclass(frozen=True)
class TargetFQI:
    """Settings of target Fitted Q-Iteration, shared by :class:`UMATL` and :class:`RL`.

    Attributes:
      features: basis of the linear regressor (a features spec, default linear);
        refused for extra-trees, which split raw states.
      regressor: ``"linear"`` or ``"extra_trees"``.
      ridge: the linear regressor's ridge (default 1e-6); refused for extra-trees.
      n_estimators: extra-trees' tree count (default 50); refused for linear.
      gamma, iterations: FQI's discount and iteration count.
    """

    features: dict | None = None
    regressor: str = "linear"
    ridge: float | None = None
    n_estimators: int | None = None
    gamma: float = 0.95
    iterations: int = 20
    name: str = "target-fqi"
    from_source = False  # UMA-TL starts from the mapped source Q

    def __post_init__(self) -> None:
        owner = type(self).__name__
        _check_choice(owner, "regressor", self.regressor, REGRESSOR_KINDS)
        for field in ("ridge", "features"):
            if getattr(self, field) is not None and self.regressor != "linear":
                raise ValueError(f"{owner}.{field} applies to regressor 'linear' only, not {self.regressor!r}")
        if self.n_estimators is not None:
            if self.regressor != "extra_trees":
                raise ValueError(f"{owner}.n_estimators applies to regressor 'extra_trees' only")
            _check_number(owner, "n_estimators", self.n_estimators, 1, integer=True)
        if self.ridge is not None:
            _check_number(owner, "ridge", self.ridge, 0.0)
        if self.regressor == "linear":
            check_features(owner, "features", self.linear_features)
        _check_number(owner, "gamma", self.gamma, 0.0, 1.0, high_open=True)
        _check_number(owner, "iterations", self.iterations, 1, integer=True)

    @property
    def linear_features(self) -> dict:
        return {"kind": "linear"} if self.features is None else self.features

    def check(self, source: TaskDescription, target: TaskDescription) -> None:
        if self.regressor == "linear":
            check_features(type(self).__name__, "features", self.linear_features, target.state_dim)

    def regressor_spec(self) -> dict:
        spec: dict = {"kind": self.regressor, "features": self.linear_features}
        if self.regressor == "linear":
            spec["ridge"] = 1e-6 if self.ridge is None else self.ridge
        elif self.n_estimators is not None:
            spec["n_estimators"] = self.n_estimators
        return spec

    def learn(self, problem: TransferProblem, target_samples: Transitions) -> Policy:
        regressor = make_regressor(self.regressor_spec(), target_samples.state_dim)
        rng = np.random.default_rng(problem.seed)
        if self.from_source:
            q = uma_tl(
                problem.source_q,
                problem.mapping,
                target_samples,
                problem.n_actions,
                regressor,
                self.gamma,
                self.iterations,
                rng=rng,
            )
        else:
            q = rl(target_samples, problem.n_actions, regressor, self.gamma, self.iterations, rng=rng)
        return GreedyPolicy(q, problem.target.action_values, problem.target.discrete)


@dataclasses.dataclass(frozen=True)
class UMATL(TargetFQI):
    """UMA-TL: target FQI initialised with the mapped source Q (Ammar et al. 2015)."""

    name: str = "uma-tl"
    from_source = True


@dataclasses.dataclass(frozen=True)
class RL(TargetFQI):
    """No transfer: target FQI from scratch."""

    name: str = "rl"


__all__ = [
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
    "check_features",
]
