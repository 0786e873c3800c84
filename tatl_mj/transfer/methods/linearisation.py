"""The exact linearisation of a one-step target model at the zero state and action, and an
affine model ``s' = A s + B a + c`` as a batched model: horizon TA-TL's oracle ablation
(``model = "oracle"``) puts the real target simulator's linearisation in the apprentice's
place.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

TargetModel = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""One batched target step: (N, dT) states, (N, mT) action values -> (N, dT) next states."""


def linearised_parts(
    step: TargetModel, state_dim: int, action_dim: int, width: float = 1e-4
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A, B, c) of the exact linearisation of a one-step model at the zero state and
    action: ``step(s, a) ~ A s + B a + c``.

    Central differences of ``step``, one query per call, so a simulator that draws
    its noise afresh from a fixed seed on every call (``sampling.step_values_from``)
    sees the same noise in each difference, and it cancels.
    """

    def query(state: np.ndarray, action: np.ndarray) -> np.ndarray:
        return np.asarray(step(state[None], action[None]), dtype=np.float64)[0]

    x0, a0 = np.zeros(state_dim), np.zeros(action_dim)
    f0 = query(x0, a0)
    A = np.empty((state_dim, state_dim))
    B = np.empty((state_dim, action_dim))
    for i, e in enumerate(np.eye(state_dim)):
        A[:, i] = (query(x0 + width * e, a0) - query(x0 - width * e, a0)) / (2 * width)
    for i, e in enumerate(np.eye(action_dim)):
        B[:, i] = (query(x0, a0 + width * e) - query(x0, a0 - width * e)) / (2 * width)
    return A, B, f0


def affine_model(parts: tuple[np.ndarray, np.ndarray, np.ndarray]) -> TargetModel:
    """``s' = A s + B a + c`` as a batched model."""
    A, B, c = parts

    def model(states: np.ndarray, action_values: np.ndarray) -> np.ndarray:
        return c + np.asarray(states) @ A.T + np.asarray(action_values).reshape(len(states), -1) @ B.T

    return model


def linearised(step: TargetModel, state_dim: int, action_dim: int, width: float = 1e-4) -> TargetModel:
    """The exact linearisation of a one-step model at the zero state and action, as a model
    (:func:`linearised_parts`)."""
    return affine_model(linearised_parts(step, state_dim, action_dim, width))


__all__ = ["TargetModel", "affine_model", "linearised", "linearised_parts"]
