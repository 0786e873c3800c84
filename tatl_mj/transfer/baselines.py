"""The two methods TA-TL is compared with in the paper.

- **UMA-TL** (Ammar et al. 2015): target FQI whose initial Q-function is the source's,
  seen through the inter-task mapping, ``Q_0(s_T, a) = Q_S(chi_plus(s_T), a)``; it then
  learns from target samples like plain FQI.
- **RL**: target FQI from scratch (Q_0 = 0), no transfer.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from tatl_mj.transfer.alignment import Mapping
from tatl_mj.transfer.fqi import QFunction, Regressor, fitted_q_iteration
from tatl_mj.transitions import Transitions


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


def uma_tl(
    source_q: QFunction,
    mapping: Mapping,
    target_transitions: Transitions,
    n_actions: int,
    regressor: Regressor,
    gamma: float,
    iterations: int,
    rng: np.random.Generator | None = None,
) -> QFunction:
    """Target FQI initialised with the mapped source Q-function (UMA-TL)."""
    if source_q.n_actions != n_actions:
        raise ValueError(f"source_q has {source_q.n_actions} actions, the target has n_actions={n_actions}")
    return fitted_q_iteration(
        target_transitions,
        n_actions,
        regressor,
        gamma,
        iterations,
        initial_q=MappedQ(source_q, mapping),
        rng=rng,
    )


def rl(
    target_transitions: Transitions,
    n_actions: int,
    regressor: Regressor,
    gamma: float,
    iterations: int,
    rng: np.random.Generator | None = None,
) -> QFunction:
    """Target FQI from scratch (the no-transfer baseline)."""
    return fitted_q_iteration(target_transitions, n_actions, regressor, gamma, iterations, rng=rng)


__all__ = ["MappedQ", "rl", "uma_tl"]
