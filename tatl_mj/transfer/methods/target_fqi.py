"""Target Fitted Q-Iteration and the methods built on it: UMA-TL, its prior variant, and RL.

- **UMA-TL** (Ammar et al. 2015): target FQI whose initial Q-function is the source's,
  seen through the inter-task mapping, ``Q_0(s_T, a) = Q_S(chi_plus(s_T), a)``
  (:class:`MappedQ`); it then learns from target samples like plain FQI.
- **UMA-TL-prior**: the mapped source Q stays in every fit (not the paper's baseline).
- **RL**: target FQI from scratch (Q_0 = 0), no transfer.

:class:`TargetFQI` is the one learner (with its data protocols) of the three methods
:class:`UMATL`, :class:`UMATLPrior` and :class:`RL`.
"""

from __future__ import annotations

import dataclasses
import warnings
from typing import ClassVar

import numpy as np

from tatl_mj.description import TaskDescription
from tatl_mj.transfer.features import FeaturesSpec, check_features
from tatl_mj.transfer.fqi import (
    NEXT_PASSES,
    PRECISIONS,
    REGRESSOR_KINDS,
    QFunction,
    fitted_q_iteration,
    greedy_each,
    make_regressor,
)
from tatl_mj.transfer.intertask_mapping import Mapping
from tatl_mj.transfer.method import Policy, TransferProblem
from tatl_mj.transfer.placebo import SOURCES
from tatl_mj.transitions import Transitions
from tatl_mj.validation import Constraints, Interval, InvalidSetting, Options, check_settings


@dataclasses.dataclass(frozen=True, eq=False)
class MappedQ:
    """``Q(s_T, a) = source_q(chi_plus(s_T), a)``: the source Q seen from the target."""

    source_q: QFunction
    mapping: Mapping

    @property
    def n_actions(self) -> int:
        return self.source_q.n_actions

    def values(self, states: np.ndarray) -> np.ndarray:
        return self.source_q.values(self.mapping.chi_plus(states))

    def greedy(self, states: np.ndarray) -> np.ndarray:
        return np.argmax(self.values(states), axis=1).astype(np.int64)


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
      precision: the linear regressor's ``"double"`` (default) or ``"single"``
        passes (see :class:`~tatl_mj.transfer.fqi.LinearRegressor`); refused for extra-trees.
      next_pass: the linear regressor's ``"matrix"`` (default) or ``"blocked"`` pass over
        the next states (the same FQI up to rounding; see
        :class:`~tatl_mj.transfer.fqi.LinearRegressor`); refused for extra-trees.
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
    precision: str | None = None
    next_pass: str | None = None
    n_estimators: int | None = None
    gamma: float = 0.95
    iterations: int = 20
    data: str = "shared"
    epsilon: float = 0.1
    online_batch: int = 100
    source: str = "trained"
    name: str = "target-fqi"
    source_use = "none"  # how the mapped source Q enters: "none", "initial" (Q_0) or "prior" (every fit)

    constraints: ClassVar[Constraints] = {
        "features": [None, FeaturesSpec()],
        "regressor": [Options(*REGRESSOR_KINDS)],
        "ridge": [None, Interval(float, 0)],
        "precision": [None, Options(*PRECISIONS)],
        "next_pass": [None, Options(*NEXT_PASSES)],
        "n_estimators": [None, Interval(int, 1)],
        "gamma": [Interval(float, 0, 1, closed="left")],
        "iterations": [Interval(int, 1)],
        "data": [Options(*DATA_PROTOCOLS)],
        "epsilon": [Interval(float, 0, 1)],
        "online_batch": [Interval(int, 1)],
        "source": [Options(*SOURCES)],
    }

    def __post_init__(self) -> None:
        check_settings(self)
        owner = type(self).__name__
        for field, regressor in (
            ("ridge", "linear"),
            ("precision", "linear"),
            ("next_pass", "linear"),
            ("features", "linear"),
            ("n_estimators", "extra_trees"),
        ):
            if getattr(self, field) is not None and self.regressor != regressor:
                raise InvalidSetting(f"{owner}.{field} applies to regressor {regressor!r} only, not {self.regressor!r}")
        if self.source == "placebo" and self.source_use == "none":
            raise InvalidSetting(
                f"{owner}.source = 'placebo' needs a learner that uses the source Q; {owner} uses none"
            )

    @property
    def uses_source(self) -> bool:
        """False for the learners that never see the mapped source Q (``rl``, ``apprentice-fqi``)."""
        return self.source_use != "none"

    @property
    def privileges(self) -> tuple[str, ...]:
        """``resets`` on the ``reset`` protocol: a simulator reset to chosen states, which a robot lacks."""
        return ("resets",) if self.data == "reset" else ()

    @property
    def linear_features(self) -> dict:
        return {"kind": "linear"} if self.features is None else self.features

    def check(self, source: TaskDescription, target: TaskDescription) -> None:
        if self.regressor == "linear":
            check_features(type(self).__name__, "features", self.linear_features, target.state_dim)
        if self.data == "reset" and target.reset_low is None and not (target.discrete and target.known_model):
            raise InvalidSetting(
                f"{type(self).__name__}.data = 'reset' needs a reset box; {target.domain}/{target.task} declares none"
            )

    def regressor_spec(self) -> dict:
        spec: dict = {"kind": self.regressor, "features": self.linear_features}
        if self.regressor == "linear":
            spec["ridge"] = 1e-6 if self.ridge is None else self.ridge
            for key in ("precision", "next_pass"):
                if getattr(self, key) is not None:
                    spec[key] = getattr(self, key)
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
                    policy = None if q is None else EpsilonGreedy(q, self.epsilon, rng, problem.target.discrete)
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


@dataclasses.dataclass(frozen=True, eq=False)
class EpsilonGreedy:
    """Index policy: greedy in ``q``, a uniformly random action with probability ``epsilon``.

    Each call draws, from ``rng``, one uniform number per state (explore below
    ``epsilon``) and then one random action per state, whatever the states are;
    so what successive one-state calls draw can be drawn first (:meth:`draws`)
    and the calls answered later, many at once (:meth:`act`), with the same
    actions (an environment's episodes stepped in lockstep).
    With ``cells`` (a discrete target, stepped one state a call) each cell's greedy
    action is computed once: the same action, without a Q evaluation a step.
    """

    q: QFunction
    epsilon: float
    rng: np.random.Generator
    cells: bool = False
    known: dict = dataclasses.field(default_factory=dict, repr=False)

    def greedy(self, states: np.ndarray) -> np.ndarray:
        if not self.cells or len(states) != 1:
            return self.q.greedy(states)
        key = np.asarray(states, np.float64).tobytes()
        if key not in self.known:
            self.known[key] = self.q.greedy(states)
        return self.known[key]

    def __call__(self, states: np.ndarray) -> np.ndarray:
        greedy = self.greedy(states)
        explore = self.rng.random(len(greedy)) < self.epsilon
        return np.where(explore, self.rng.integers(self.q.n_actions, size=len(greedy)), greedy)

    def draws(self, calls: int) -> np.ndarray:
        """(calls, 2): what ``calls`` successive one-state calls draw, in their order
        (the uniform number, the random action), drawn now."""
        # A scalar draw takes what a one-element draw takes from the generator (tested).
        random, integers, n = self.rng.random, self.rng.integers, self.q.n_actions
        return np.array([(random(), integers(n)) for _ in range(calls)], np.float64).reshape(calls, 2)

    def act(self, states: np.ndarray, draws: np.ndarray) -> np.ndarray:
        """(N,) what one-state calls on each row of ``states`` return, the row having drawn ``draws``' row."""
        if self.cells and len(states) == 1:  # a cell a call (grid collections): scalars, the same answer
            uniform, action = draws[0]
            return np.array([int(action)]) if uniform < self.epsilon else self.greedy(states)
        return np.where(draws[:, 0] < self.epsilon, draws[:, 1].astype(np.int64), greedy_each(self.q, states))


@dataclasses.dataclass(frozen=True)
class UMATL(TargetFQI):
    """UMA-TL: target FQI initialised with the mapped source Q (Ammar et al. 2015).

    The mapped source Q is only the first iteration's bootstrap: after enough
    iterations its influence is gone (see :class:`UMATLPrior`)."""

    name: str = "uma-tl"
    source_use = "initial"
    baseline = True  # the paper's transfer baseline


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
    baseline = True  # the paper's baseline without transfer

    @property
    def ablation_of(self) -> tuple[str, ...]:
        """The UMA-TL learners on the same data protocol: the same FQI without the mapped source Q
        (none on the online protocol, which no UMA-TL learner uses)."""
        return {"shared": ("uma-tl", "uma-tl-prior"), "reset": ("uma-tl-reset",)}.get(self.data, ())


__all__ = [
    "DATA_PROTOCOLS",
    "EpsilonGreedy",
    "RL",
    "UMATL",
    "GreedyPolicy",
    "MappedQ",
    "TargetFQI",
    "UMATLPrior",
]
