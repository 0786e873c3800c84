"""A target's reward and end condition learned from the rewards and ends its samples observed.

A model-based learner that may not call the task's own reward function
(``apprentice-fqi-samples``) scores its model's transitions with :class:`RewardModel`:
a ridge least squares of the observed rewards, and a least-squares classifier of the
observed ends (``absorbing``, 1 or 0, thresholded at one half), both on one design
built from a basis phi (one features spec, or several side by side):

- ``inputs = "next"``: phi(s'), for a reward of the state a step reaches (the
  pendulum's -10 theta^2 - 5 theta_dot^2, the mountain car's, the bicycle's);
- ``inputs = "transition"``: phi(s') and, per action, phi(s) (a block per action,
  zero for the others), for a reward of the step itself (the grid world's bumps).

:func:`held_out_errors` says how well such a model predicts samples it was not fitted on.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Sequence

import numpy as np

from tatl_mj.transfer.features import Features, make_features
from tatl_mj.transitions import Transitions

REWARD_INPUTS = ("next", "transition")
"""What the reward model's design is built from (see the module docstring)."""


def reward_bases(spec: Any, state_dim: int) -> tuple[Features, ...]:
    """The bases a reward features setting names: one features spec, or a list of them side by side."""
    specs = spec if isinstance(spec, (list, tuple)) else (spec,)
    return tuple(make_features(s, state_dim) for s in specs)


@dataclasses.dataclass(frozen=True, eq=False)
class RewardModel:
    """``r(s, a, s') = w . x(s, a, s')`` and ``end(s') = v . x(s, a, s') > 1/2``.

    Attributes:
      bases: the basis phi, its parts side by side.
      inputs: ``"next"`` or ``"transition"`` (see the module docstring).
      n_actions: the target's action count (the transition design's blocks).
      reward_weights: (k,) w.
      end_weights: (k,) v, or None where no sample ended (the model then never ends).
    """

    bases: tuple[Features, ...]
    inputs: str
    n_actions: int
    reward_weights: np.ndarray
    end_weights: np.ndarray | None

    def predict(
        self, states: np.ndarray, actions: np.ndarray, next_states: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(N,) rewards and (N,) bool ends of the steps ``states`` --``actions``--> ``next_states``."""
        x = design(self.bases, self.inputs, self.n_actions, states, actions, next_states)
        rewards = x @ self.reward_weights
        ends = np.zeros(len(x), bool) if self.end_weights is None else x @ self.end_weights > 0.5
        return rewards, ends


def design(
    bases: Sequence[Features],
    inputs: str,
    n_actions: int,
    states: np.ndarray,
    actions: np.ndarray,
    next_states: np.ndarray,
) -> np.ndarray:
    """(N, k) the regressors of steps: phi(s'), and for ``"transition"`` phi(s) in its action's block."""
    after = np.hstack([basis(np.asarray(next_states, np.float64)) for basis in bases])
    if inputs == "next":
        return after
    before = np.hstack([basis(np.asarray(states, np.float64)) for basis in bases])
    blocks = np.zeros((len(before), n_actions, before.shape[1]))
    blocks[np.arange(len(before)), np.asarray(actions, np.int64)] = before
    return np.hstack([after, blocks.reshape(len(before), -1)])


def _ridge(x: np.ndarray, y: np.ndarray, ridge: float) -> np.ndarray:
    """argmin |x w - y|^2 + ridge |w|^2 (the least-norm solution where ridge = 0 leaves it open)."""
    gram = x.T @ x + ridge * np.eye(x.shape[1])
    return np.linalg.lstsq(gram, x.T @ y, rcond=None)[0]


def fit_reward_model(
    data: Transitions, bases: Sequence[Features], inputs: str, n_actions: int, ridge: float
) -> RewardModel:
    """The reward and end model of ``data``'s observed rewards and ends."""
    if inputs not in REWARD_INPUTS:
        raise ValueError(f"inputs must be one of {list(REWARD_INPUTS)}, got {inputs!r}")
    x = design(bases, inputs, n_actions, data.states, data.actions, data.next_states)
    ends = data.absorbing.astype(np.float64)
    return RewardModel(
        bases=tuple(bases),
        inputs=inputs,
        n_actions=int(n_actions),
        reward_weights=_ridge(x, data.rewards, ridge),
        end_weights=_ridge(x, ends, ridge) if ends.any() else None,
    )


@dataclasses.dataclass(frozen=True)
class HeldOutErrors:
    """How a reward model fitted without them predicts held-out samples.

    Attributes:
      samples: how many were held out (0: none, and the errors are None).
      reward_rmse: root mean square error of the predicted rewards (reward units).
      reward_scale: the held-out rewards' standard deviation (a model that predicts their
        mean has ``reward_rmse`` about this).
      end_error: the fraction of held-out samples whose end (absorbing) is mispredicted.
    """

    samples: int
    reward_rmse: float | None = None
    reward_scale: float | None = None
    end_error: float | None = None


def held_out_errors(
    data: Transitions,
    bases: Sequence[Features],
    inputs: str,
    n_actions: int,
    ridge: float,
    holdout: float,
    rng: np.random.Generator,
) -> HeldOutErrors:
    """A model's errors on a random ``holdout`` fraction of ``data``, fitted on the rest.

    None of them where the fraction leaves nothing to hold out or nothing to fit on.
    """
    n = len(data)
    held = int(math.floor(holdout * n))
    if held < 1 or held >= n:
        return HeldOutErrors(samples=0)
    order = rng.permutation(n)
    test, train = _subset(data, order[:held]), _subset(data, order[held:])
    model = fit_reward_model(train, bases, inputs, n_actions, ridge)
    rewards, ends = model.predict(test.states, test.actions, test.next_states)
    with np.errstate(all="ignore"):
        rmse = float(np.sqrt(np.mean((rewards - test.rewards) ** 2)))
    return HeldOutErrors(
        samples=held,
        reward_rmse=rmse,
        reward_scale=float(np.std(test.rewards)),
        end_error=float(np.mean(ends != test.absorbing)),
    )


def _subset(data: Transitions, rows: np.ndarray) -> Transitions:
    return Transitions(
        states=data.states[rows],
        actions=data.actions[rows],
        rewards=data.rewards[rows],
        next_states=data.next_states[rows],
        absorbing=data.absorbing[rows],
        last=data.last[rows],
    )


__all__ = [
    "REWARD_INPUTS",
    "HeldOutErrors",
    "RewardModel",
    "design",
    "fit_reward_model",
    "held_out_errors",
    "reward_bases",
]
