"""The inter-task mapping's contract (:class:`Mapping`: chi, source -> target, and
chi_plus, target -> source) and the two given maps: :class:`IdentityMapping` for
same-domain experiments and :class:`AffineMapping` for a known affine map (also what
:func:`tatl_mj.transfer.transition_alignment.align_transitions` returns). The learned
maps of Phase II are in ``manifold_alignment`` (the paper's) and ``transition_alignment``.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Protocol, runtime_checkable

import numpy as np

from tatl_mj.transfer.features import as_states


@runtime_checkable
class Mapping(Protocol):
    """An inter-task state mapping: chi (source -> target) and chi_plus (target -> source)."""

    def chi(self, source_states: np.ndarray) -> np.ndarray:
        """(N, dS) source states -> (N, dT) their images in the target state space."""
        ...

    def chi_plus(self, target_states: np.ndarray) -> np.ndarray:
        """(N, dT) target states -> (N, dS) their images in the source state space."""
        ...


@dataclasses.dataclass(frozen=True)
class IdentityMapping:
    """chi = chi_plus = identity (same-domain transfer: the state spaces coincide)."""

    def chi(self, source_states: np.ndarray) -> np.ndarray:
        return as_states(source_states, "source_states").copy()

    def chi_plus(self, target_states: np.ndarray) -> np.ndarray:
        return as_states(target_states, "target_states").copy()


@dataclasses.dataclass(frozen=True, eq=False)
class AffineMapping:
    """``chi(s_S) = matrix s_S + offset``; ``chi_plus`` is its least-squares inverse.

    Attributes:
      matrix: (dT, dS).
      offset: (dT,).
    """

    matrix: np.ndarray
    offset: np.ndarray

    def __post_init__(self) -> None:
        m = np.atleast_2d(np.asarray(self.matrix, dtype=np.float64))
        o = np.asarray(self.offset, dtype=np.float64).ravel()
        if m.ndim != 2 or o.shape != (m.shape[0],):
            raise ValueError(f"AffineMapping.matrix (dT, dS) and offset (dT,) disagree: {m.shape}, {o.shape}")
        if not (np.all(np.isfinite(m)) and np.all(np.isfinite(o))):
            raise ValueError("AffineMapping.matrix and offset must be finite")
        object.__setattr__(self, "matrix", m)
        object.__setattr__(self, "offset", o)

    @functools.cached_property
    def _inverse(self) -> np.ndarray:
        return np.linalg.pinv(self.matrix)

    def chi(self, source_states: np.ndarray) -> np.ndarray:
        s = as_states(source_states, "source_states", self.matrix.shape[1])
        return s @ self.matrix.T + self.offset

    def chi_plus(self, target_states: np.ndarray) -> np.ndarray:
        s = as_states(target_states, "target_states", self.matrix.shape[0])
        return (s - self.offset) @ self._inverse.T


__all__ = [
    "AffineMapping",
    "IdentityMapping",
    "Mapping",
]
