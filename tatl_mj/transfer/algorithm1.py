"""The TA-TL policy: Algorithm 1 of the paper, batched over target states.

For each target state s^T_i (paper symbols; eq. numbers refer to the paper's labels):

1. ``s_hat_S  = chi_plus(s_T)``                         project into the source
2. ``a_S      = argmax_a Q_S(s_hat_S, a)``              greedy source action
3. ``s_S_next = P_S(s_hat_S, a_S)``                     query the source simulator (one step)
4. ``s_hat_T_next = chi(s_S_next)``                     project back (eq. ``projected_model``)
5. ``a_T      = target_actions[a_S]``                   same index (Assumption 1)
6. ``pi_ad    = s_hat_T_next - P_hat_T(s_T, a_T)``      adaptive term (eq. ``adaptive_term``),
                                                        wrapped on the apprentice's periodic coordinates
7. ``a        = a_T + K pi_ad``, ``K = pinv(B_hat)``    TA-TL policy (eq. ``modified_optimal_policy``)

then clipped to the target actuator's ``[target_low, target_high]`` or snapped to the
nearest admissible action of ``adaptive_actions`` (the paper's A^(T)_ad).

With the apprentice ``P_hat_T(s, a) = W phi(s) + B_hat a`` (eq. ``Apprentice_model``),
step 7 reads ``a = K (s_hat_T_next - W phi(s_T))``: the action that makes the apprentice
land on the projected source next state, which is why the target then follows the
projected source trajectory (eq. ``Source_model_equation``) and why a flipped control
sign in the target flips the action (the paper's negative-transfer argument).

:class:`DiscreteTATLPolicy` is the same idea for a target whose actions are indices
(the windy grid world): it picks the target action whose apprentice prediction lands
nearest ``s_hat_T_next``.

Angles: on the apprentice's ``periodic`` coordinates both policies take differences
the shorter way round the circle (``Apprentice.difference``), so a projected next
angle of -3.1 against a prediction of 3.1 is a gap of 0.08, not -6.2.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Callable, ClassVar

import numpy as np

from tatl_mj.transfer.apprentice import Apprentice
from tatl_mj.transfer.features import as_states
from tatl_mj.transfer.fqi import QFunction
from tatl_mj.transfer.intertask_mapping import Mapping
from tatl_mj.validation import Array, Constraints, Function, check_settings

SourceStep = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""One batched source-simulator step: (N, dS) states, (N,) action indices -> (N, dS)."""


@dataclasses.dataclass(frozen=True)
class TATLStep:
    """Every quantity of one TA-TL decision, in the paper's symbols (all batched)."""

    s_hat_S: np.ndarray  # (N, dS) chi_plus(s_T)
    a_S: np.ndarray  # (N,) greedy source action index
    s_S_next: np.ndarray  # (N, dS) source simulator's next state
    s_hat_T_next: np.ndarray  # (N, dT) chi(s_S_next), the projected source next state
    a_T: np.ndarray  # (N, mT) target action of the same index (Assumption 1)
    pi_ad: np.ndarray  # (N, dT) s_hat_T_next - P_hat_T(s_T, a_T), wrapped on periodic coordinates
    adaptive: np.ndarray  # (N, mT) K pi_ad
    action: np.ndarray  # (N, mT) a_T + K pi_ad, clipped or snapped


@dataclasses.dataclass(frozen=True)
class PremiseStep:
    """What one batch of decisions shows the premises' measurements (``tatl_mj.transfer.premises``).

    Attributes:
      action: (N, mT) the action values the policy returns, exactly its ``__call__``'s.
      requested: (N, mT) ``a_T + K pi_ad`` before any clip or snap; None where the
        policy has no such request (a discrete target's).
      projected: (N, dT) ``s_hat_T_next``, the projected source next state; None where not formed.
      predicted: (N, dT) the policy's own model's next state for ``action`` (delta's or the
        misprediction's prediction); None where the observer predicts with ``policy.apprentice``.
    """

    action: np.ndarray
    requested: np.ndarray | None = None
    projected: np.ndarray | None = None
    predicted: np.ndarray | None = None


_POLICY: Constraints = {
    "source_step": [Function("(states (N, dS), action indices (N,)) -> (N, dS)")],
    "source_actions": [Array(2)],
    "target_actions": [Array(2)],
    "adaptive_actions": [None, Array(2)],
}
"""What both policies' action settings admit (a 1-D action set is a column)."""


def _source_decision(
    policy: "TATLPolicy | DiscreteTATLPolicy", target_states: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Steps 1-4 of Algorithm 1: s_T, s_hat_S, a_S, s_S_next, s_hat_T_next."""
    s_T = as_states(target_states, "target_states", policy.apprentice.state_dim)
    s_hat_S = policy.mapping.chi_plus(s_T)
    a_S = np.asarray(policy.source_q.greedy(s_hat_S), dtype=np.int64)
    s_S_next = np.asarray(policy.source_step(s_hat_S, a_S), dtype=np.float64)
    if s_S_next.shape != s_hat_S.shape:
        raise ValueError(f"source_step returned shape {s_S_next.shape}, expected {s_hat_S.shape}")
    s_hat_T_next = policy.mapping.chi(s_S_next)
    return s_T, s_hat_S, a_S, s_S_next, s_hat_T_next


def _check_common(policy: "TATLPolicy | DiscreteTATLPolicy") -> None:
    check_settings(policy)
    if not isinstance(policy.apprentice, Apprentice):
        raise ValueError(f"apprentice must be an Apprentice, got {type(policy.apprentice).__name__}")
    n_s, n_t = len(policy.source_actions), len(policy.target_actions)
    if n_s != n_t:
        raise ValueError(f"source_actions ({n_s}) and target_actions ({n_t}) must have the same count (Assumption 1)")
    if policy.source_q.n_actions != n_s:
        raise ValueError(f"source_q has {policy.source_q.n_actions} actions, source_actions has {n_s}")


@dataclasses.dataclass(frozen=True, eq=False)
class TATLPolicy:
    """pi*(T)(s) = pi*(S)(chi(s)) + K pi_ad(s): Algorithm 1 for a continuous-actuator target.

    Attributes:
      source_q: Q_S, the source task's action values (Phase I).
      mapping: chi / chi_plus (Phase II).
      source_step: P_S, one batched step of the source simulator.
      apprentice: P_hat_T(s, a) = W phi(s) + B_hat a.
      source_actions: (n, mS) the source's discrete action set.
      target_actions: (n, mT) the target's; row i corresponds to source row i.
      target_low, target_high: (mT,) actuator limits the result is clipped to (one
        entry: the same limit for every column).
      adaptive_actions: optional (n_ad, mT) admissible set A_ad; when given the
        action is snapped to its nearest row (after clipping) instead.
      samples_used: target samples the apprentice used (Algorithm 2), for reports.
    """

    source_q: QFunction
    mapping: Mapping
    source_step: SourceStep
    apprentice: Apprentice
    source_actions: np.ndarray
    target_actions: np.ndarray
    target_low: np.ndarray
    target_high: np.ndarray
    adaptive_actions: np.ndarray | None = None
    samples_used: int | None = None

    constraints: ClassVar[Constraints] = {
        **_POLICY,
        "target_low": [Array(1, finite=False)],
        "target_high": [Array(1, finite=False)],
    }

    def __post_init__(self) -> None:
        _check_common(self)
        m = self.target_actions.shape[1]
        if self.apprentice.action_dim != m:
            raise ValueError(f"apprentice.B has {self.apprentice.action_dim} columns, target actions have {m}")
        low, high = self.target_low, self.target_high
        if low.size not in (1, m) or high.size not in (1, m) or np.any(low > high):
            raise ValueError(f"target_low must be <= target_high, one or {m} entries each, got {low} and {high}")
        ad = self.adaptive_actions
        if ad is not None and (ad.shape[1] != m or np.any(ad < low) or np.any(ad > high)):
            raise ValueError(f"adaptive_actions must be (n_ad, {m}) rows within [target_low, target_high]")
        if np.linalg.matrix_rank(self.apprentice.B) < m:
            raise ValueError(
                f"apprentice.B_hat has rank {np.linalg.matrix_rank(self.apprentice.B)} < {m}: "
                "the target's actions have no identified effect, K = pinv(B_hat) is meaningless"
            )

    @functools.cached_property
    def K(self) -> np.ndarray:
        """pinv(B_hat), the mixture gain."""
        return np.linalg.pinv(self.apprentice.B)

    def step(self, target_states: np.ndarray) -> TATLStep:
        """Runs Algorithm 1 on (N, dT) target states and returns every intermediate."""
        s_T, s_hat_S, a_S, s_S_next, s_hat_T_next = _source_decision(self, target_states)
        a_T = self.target_actions[a_S]
        pi_ad = self.apprentice.difference(s_hat_T_next, self.apprentice.predict(s_T, a_T))
        adaptive = pi_ad @ self.K.T
        action = np.clip(a_T + adaptive, self.target_low, self.target_high)
        if self.adaptive_actions is not None:
            gaps = np.linalg.norm(action[:, None, :] - self.adaptive_actions[None, :, :], axis=2)
            action = self.adaptive_actions[np.argmin(gaps, axis=1)]
        return TATLStep(s_hat_S, a_S, s_S_next, s_hat_T_next, a_T, pi_ad, adaptive, action)

    def __call__(self, target_states: np.ndarray) -> np.ndarray:
        """(N, dT) target states -> (N, mT) target action values."""
        return self.step(target_states).action

    def premise_step(self, target_states: np.ndarray) -> PremiseStep:
        """The method contract's ``premise_step`` hook: the same decision as ``__call__``
        (one :meth:`step`), with the request before clipping and s_hat_T_next beside it."""
        step = self.step(target_states)
        return PremiseStep(step.action, step.a_T + step.adaptive, step.s_hat_T_next)


@dataclasses.dataclass(frozen=True, eq=False)
class DiscreteTATLPolicy:
    """Algorithm 1 for a target whose actions are indices (no continuous actuator).

    ``target_actions`` (n, mT) are the action values the apprentice was fitted with
    (e.g. a grid move's [d_row, d_col]); the policy returns the index i whose
    prediction ``P_hat_T(s_T, target_actions[i])`` is nearest ``s_hat_T_next``; ties go
    to the source's own index a_S. ``target_low``/``target_high``/``adaptive_actions``
    are accepted for a uniform signature and unused.
    """

    source_q: QFunction
    mapping: Mapping
    source_step: SourceStep
    apprentice: Apprentice
    source_actions: np.ndarray
    target_actions: np.ndarray
    target_low: np.ndarray | None = None
    target_high: np.ndarray | None = None
    adaptive_actions: np.ndarray | None = None
    samples_used: int | None = None

    constraints: ClassVar[Constraints] = _POLICY

    def __post_init__(self) -> None:
        _check_common(self)
        m = self.target_actions.shape[1]
        if self.apprentice.action_dim != m:
            raise ValueError(f"apprentice.B has {self.apprentice.action_dim} columns, target actions have {m}")

    def distances(self, target_states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, n) |P_hat_T(s_T, a_i) - s_hat_T_next| for every target action, and a_S
        (the difference wrapped on the apprentice's periodic coordinates)."""
        s_T, _, a_S, _, s_hat_T_next = _source_decision(self, target_states)
        n, n_actions = len(s_T), len(self.target_actions)
        drift = self.apprentice.drift(s_T)  # (N, d)
        predictions = drift[:, None, :] + (self.target_actions @ self.apprentice.B.T)[None, :, :]
        gaps = self.apprentice.difference(predictions, s_hat_T_next[:, None, :])
        return np.linalg.norm(gaps, axis=2).reshape(n, n_actions), a_S

    def __call__(self, target_states: np.ndarray) -> np.ndarray:
        """(N, dT) target states -> (N,) int64 target action indices."""
        dist, a_S = self.distances(target_states)
        best = dist.min(axis=1, keepdims=True)
        near = dist <= best + 1e-9 * (1.0 + best)
        rows = np.arange(len(dist))
        return np.where(near[rows, a_S], a_S, np.argmax(near, axis=1)).astype(np.int64)

    def premise_step(self, target_states: np.ndarray) -> PremiseStep:
        """The method contract's ``premise_step`` hook: ``__call__``'s indices; an index
        is always feasible and the grid's measure is the apprentice's misprediction."""
        return PremiseStep(self(target_states))

    premise_measures: ClassVar[tuple[str, ...]] = ("misprediction",)
    """The premises measured for it (``run.premises.measures_of``): the grid's delta."""


__all__ = ["DiscreteTATLPolicy", "PremiseStep", "SourceStep", "TATLPolicy", "TATLStep"]
