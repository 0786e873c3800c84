"""The plug-in interface: what a transfer method gets, and what it must return.

A method is anything with a ``name`` and ``learn(problem, target_samples) -> Policy``
(the :class:`TransferMethod` protocol). :class:`TransferProblem` bundles everything a
method may use: the source's Q-function and simulator step, the inter-task mapping,
both action sets, the target actuator's limits, the basis and regressor settings.
``target_samples`` are the target transitions the method is allowed to see (its
budget); a method must not step the target any other way.

The built-ins are :class:`TATL` (the paper's Algorithms 1 and 2), :class:`UMATL` and
:class:`RL`, listed in the explicit ``METHODS`` dict. To compare your own method,
pass an instance of it next to these to the experiment runner.
"""

from __future__ import annotations

import dataclasses
from typing import Callable, Protocol, runtime_checkable

import numpy as np

from tatl_mj.transfer.alignment import Mapping
from tatl_mj.transfer.apprentice import Apprentice, fit_apprentice, learn_apprentice
from tatl_mj.transfer.baselines import rl, uma_tl
from tatl_mj.transfer.features import Features
from tatl_mj.transfer.fqi import QFunction, make_regressor
from tatl_mj.transfer.tatl import DiscreteTATLPolicy, SourceStep, TATLPolicy
from tatl_mj.transitions import Transitions

Policy = Callable[[np.ndarray], np.ndarray]
"""Batched target policy: (N, dT) states -> (N, mT) action values, or (N,) indices for a discrete target."""


@dataclasses.dataclass(frozen=True, eq=False)
class TransferProblem:
    """Everything a transfer method may use besides the target samples.

    Attributes:
      source_q: Q_S learned on the source (Phase I).
      mapping: chi / chi_plus between the state spaces (Phase II).
      source_step: one batched source-simulator step, (N, dS), (N,) indices -> (N, dS).
      source_actions: (n, mS) the source's discrete action values.
      target_actions: (n, mT) the target's; row i corresponds to source row i
        (Assumption 1). For a discrete target, the values the apprentice uses
        (e.g. grid moves [d_row, d_col]).
      target_low, target_high: (mT,) actuator limits (ignored for a discrete target).
      target_discrete: the target takes action indices, not actuator values.
      apprentice_features: basis phi for the apprentice (TA-TL); also readable as ``features``.
      regressor: spec dict for target FQI (``fqi.make_regressor``), used by UMA-TL and RL.
      gamma, iterations: target FQI's discount and iteration count.
      seed: seeds every random choice a method makes.
      adaptive_actions: optional (n_ad, mT) admissible set A_ad for TA-TL.
      utility_gap: optional U_M(pi) - U_Mhat(pi) of Algorithm 2 (needs the target
        simulator, so the runner builds it); without it TA-TL fits its apprentice
        on all the samples it is given.
      zeta: Algorithm 2's threshold on |utility_gap|.
      apprentice_batch: Algorithm 2's sample increment (default: all samples at once).
      apprentice_ridge: ridge of the apprentice's least squares (0: plain least squares).
      apprentice_periodic: per target state coordinate, whether it is an angle
        (the apprentice then works on wrapped increments; see ``apprentice``).
    """

    source_q: QFunction
    mapping: Mapping
    source_step: SourceStep
    source_actions: np.ndarray
    target_actions: np.ndarray
    target_low: np.ndarray | None
    target_high: np.ndarray | None
    target_discrete: bool
    apprentice_features: Features
    regressor: dict
    gamma: float
    iterations: int
    seed: int = 0
    adaptive_actions: np.ndarray | None = None
    utility_gap: Callable[[Apprentice], float] | None = None
    zeta: float = 0.0
    apprentice_batch: int | None = None
    apprentice_ridge: float = 0.0
    apprentice_periodic: tuple[bool, ...] | None = None

    def __post_init__(self) -> None:
        if not self.target_discrete and (self.target_low is None or self.target_high is None):
            raise ValueError("TransferProblem.target_low and target_high are required for a continuous target")
        if not 0.0 <= self.gamma < 1.0:
            raise ValueError(f"TransferProblem.gamma must be in [0, 1), got {self.gamma!r}")

    @property
    def features(self) -> Features:
        return self.apprentice_features

    @property
    def n_actions(self) -> int:
        return len(self.target_actions)


@runtime_checkable
class TransferMethod(Protocol):
    """A transfer method that the experiments can compare."""

    name: str

    def learn(self, problem: TransferProblem, target_samples: Transitions) -> Policy: ...


@dataclasses.dataclass(frozen=True, eq=False)
class GreedyPolicy:
    """The greedy policy of a target Q-function, as action values (or indices if discrete)."""

    q: QFunction
    target_actions: np.ndarray
    discrete: bool = False

    def __call__(self, target_states: np.ndarray) -> np.ndarray:
        idx = self.q.greedy(target_states)
        return idx if self.discrete else np.asarray(self.target_actions, dtype=np.float64).reshape(
            len(self.target_actions), -1
        )[idx]


@dataclasses.dataclass(frozen=True)
class TATL:
    """Target Apprentice TL: apprentice by Algorithm 2, policy by Algorithm 1."""

    name: str = "ta-tl"

    def learn(self, problem: TransferProblem, target_samples: Transitions) -> Policy:
        actions = np.asarray(problem.target_actions, dtype=np.float64)
        actions = actions[:, None] if actions.ndim == 1 else actions
        if problem.utility_gap is None:
            apprentice = fit_apprentice(
                target_samples.states, actions[target_samples.actions], target_samples.next_states,
                problem.apprentice_features, problem.apprentice_ridge, periodic=problem.apprentice_periodic,
            )
            used = len(target_samples)
        else:
            apprentice, used = learn_apprentice(
                target_samples, actions, problem.apprentice_features, problem.utility_gap, problem.zeta,
                problem.apprentice_batch or len(target_samples), problem.apprentice_ridge,
                periodic=problem.apprentice_periodic,
            )
        common = dict(
            source_q=problem.source_q, mapping=problem.mapping, source_step=problem.source_step,
            apprentice=apprentice, source_actions=problem.source_actions, target_actions=actions,
            target_low=problem.target_low, target_high=problem.target_high,
            adaptive_actions=problem.adaptive_actions, samples_used=used,
        )
        return DiscreteTATLPolicy(**common) if problem.target_discrete else TATLPolicy(**common)


def _target_fqi(problem: TransferProblem, target_samples: Transitions, initial: Mapping | None) -> Policy:
    """Target FQI on ``target_samples`` (from the mapped source Q when ``initial`` is a mapping)."""
    regressor = make_regressor(problem.regressor, target_samples.state_dim)
    rng = np.random.default_rng(problem.seed)
    if initial is None:
        q = rl(target_samples, problem.n_actions, regressor, problem.gamma, problem.iterations, rng=rng)
    else:
        q = uma_tl(
            problem.source_q, initial, target_samples, problem.n_actions, regressor,
            problem.gamma, problem.iterations, rng=rng,
        )
    return GreedyPolicy(q, problem.target_actions, problem.target_discrete)


@dataclasses.dataclass(frozen=True)
class UMATL:
    """UMA-TL: target FQI initialised with the mapped source Q (Ammar et al. 2015)."""

    name: str = "uma-tl"

    def learn(self, problem: TransferProblem, target_samples: Transitions) -> Policy:
        return _target_fqi(problem, target_samples, problem.mapping)


@dataclasses.dataclass(frozen=True)
class RL:
    """No transfer: target FQI from scratch."""

    name: str = "rl"

    def learn(self, problem: TransferProblem, target_samples: Transitions) -> Policy:
        return _target_fqi(problem, target_samples, None)


METHODS: dict[str, TransferMethod] = {"ta-tl": TATL(), "uma-tl": UMATL(), "rl": RL()}

__all__ = ["GreedyPolicy", "METHODS", "Policy", "RL", "TATL", "TransferMethod", "TransferProblem", "UMATL"]
