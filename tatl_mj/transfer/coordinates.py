"""The coordinates an inter-task mapping works in, chosen per domain.

A domain's state convention need not suit a map between tasks. The pendulum's
angle is measured from upright and wrapped at +-pi, which is exactly where it
hangs: random-policy data then form two clusters at +-pi, and any smooth map
(learned or hand-coded) tears the hanging position in two. Measured from
hanging instead (``phi = wrap(theta - pi)``) the same data form one cloud around
0, and an affine map such as the energy-consistent ``x = -pi/6 + phi/3`` is
meaningful.

:class:`Coordinates` re-centres each periodic coordinate at its ``origin`` and
wraps it into [-pi, pi); :class:`InCoordinates` lets any :class:`Mapping` work
in those coordinates, converting (and wrapping) states on the way in and out, so
its images are valid states of the other domain.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from tatl_mj.transfer.features import as_states, wrap_angle
from tatl_mj.transfer.intertask_mapping import Mapping
from tatl_mj.transfer.transition_alignment import SourceStep, TransitionAlignment, align_transitions
from tatl_mj.transitions import Transitions


@dataclasses.dataclass(frozen=True)
class Coordinates:
    """A domain's mapping coordinates: periodic coordinates re-centred at ``origin``.

    ``to_mapping`` sends a state ``s`` to ``c`` with ``c_k = wrap(s_k - origin_k)``
    on periodic coordinates (wrap: into [-pi, pi)) and ``c_k = s_k`` elsewhere;
    ``from_mapping`` is its inverse, ``s_k = wrap(c_k + origin_k)``. Non-periodic
    coordinates are left alone (their origin must be 0): an affine map absorbs
    their offset, while a periodic coordinate's origin decides where it is cut.

    Attributes:
      periodic: one flag per state coordinate, True for an angle.
      origin: one angle (rad) per coordinate; where that angle's mapping coordinate is 0.
    """

    periodic: tuple[bool, ...]
    origin: tuple[float, ...]

    def __post_init__(self) -> None:
        periodic = tuple(np.asarray(self.periodic).ravel().tolist())
        if not periodic or not all(isinstance(p, bool) for p in periodic):
            raise ValueError(f"Coordinates.periodic must be one bool per state coordinate, got {self.periodic!r}")
        origin = np.asarray(self.origin, dtype=np.float64).ravel()
        if origin.shape != (len(periodic),):
            raise ValueError(
                f"Coordinates.origin must hold one number per state coordinate ({len(periodic)}), got {self.origin!r}"
            )
        if not np.all(np.isfinite(origin)):
            raise ValueError(f"Coordinates.origin must be finite, got {self.origin!r}")
        moved = [k for k, (p, o) in enumerate(zip(periodic, origin)) if not p and o != 0.0]
        if moved:
            raise ValueError(
                f"Coordinates.origin must be 0 on non-periodic coordinates (an affine map absorbs "
                f"their offset), got {origin[moved].tolist()} at {moved}"
            )
        object.__setattr__(self, "periodic", periodic)
        object.__setattr__(self, "origin", tuple(origin.tolist()))

    @staticmethod
    def plain(dim: int) -> "Coordinates":
        """The state coordinates themselves: nothing periodic, nothing moved."""
        return Coordinates((False,) * dim, (0.0,) * dim)

    @property
    def dim(self) -> int:
        return len(self.periodic)

    def _shift(self, x: np.ndarray, name: str, sign: float) -> np.ndarray:
        out = as_states(x, name, self.dim).copy()
        mask = np.asarray(self.periodic)
        out[:, mask] = wrap_angle(out[:, mask] + sign * np.asarray(self.origin)[mask])
        return out

    def to_mapping(self, states: np.ndarray) -> np.ndarray:
        """(N, d) domain states -> (N, d) mapping coordinates (periodic ones re-centred, wrapped)."""
        return self._shift(states, "states", -1.0)

    def from_mapping(self, coords: np.ndarray) -> np.ndarray:
        """(N, d) mapping coordinates -> (N, d) domain states (periodic ones wrapped to [-pi, pi))."""
        return self._shift(coords, "coords", 1.0)

    def transitions(self, batch: Transitions) -> Transitions:
        """``batch`` with states and next states in mapping coordinates (the rest unchanged)."""
        return dataclasses.replace(
            batch,
            states=self.to_mapping(batch.states),
            next_states=self.to_mapping(batch.next_states),
        )

    def step(self, step: SourceStep) -> SourceStep:
        """A batched step function on domain states, seen in mapping coordinates."""

        def in_coordinates(coords: np.ndarray, actions: np.ndarray) -> np.ndarray:
            return self.to_mapping(step(self.from_mapping(coords), actions))

        return in_coordinates


@dataclasses.dataclass(frozen=True, eq=False)
class InCoordinates:
    """``inner`` applied in mapping coordinates: ``chi = T.from o inner.chi o S.to`` (likewise chi_plus).

    Any :class:`Mapping` (an alignment, an :class:`AffineMapping` written by
    hand) then maps between the domains' own state conventions, and periodic
    images come out wrapped, as the other domain's states are.

    Attributes:
      inner: the map between mapping coordinates.
      source, target: each domain's :class:`Coordinates`.
    """

    inner: Mapping
    source: Coordinates
    target: Coordinates

    def __post_init__(self) -> None:
        if not isinstance(self.inner, Mapping):
            raise ValueError(f"InCoordinates.inner must be a Mapping (chi, chi_plus), got {type(self.inner).__name__}")
        for name in ("source", "target"):
            if not isinstance(getattr(self, name), Coordinates):
                kind = type(getattr(self, name)).__name__
                raise ValueError(f"InCoordinates.{name} must be Coordinates, got {kind}")

    def chi(self, source_states: np.ndarray) -> np.ndarray:
        return self.target.from_mapping(self.inner.chi(self.source.to_mapping(source_states)))

    def chi_plus(self, target_states: np.ndarray) -> np.ndarray:
        return self.source.from_mapping(self.inner.chi_plus(self.target.to_mapping(target_states)))


def align_in_coordinates(
    source: Transitions,
    target: Transitions,
    source_coordinates: Coordinates,
    target_coordinates: Coordinates,
    n_source_actions: int,
    n_target_actions: int,
    source_step: SourceStep | None = None,
    settings: TransitionAlignment = TransitionAlignment(),
    rng: np.random.Generator | None = None,
) -> tuple[InCoordinates, dict[str, Any]]:
    """:func:`~tatl_mj.transfer.transition_alignment.align_transitions` in each domain's mapping coordinates.

    The transitions (and ``source_step``, if given) are converted to mapping
    coordinates, the affine map is learned there, and the result is wrapped in
    :class:`InCoordinates`. Returns the mapping and the learned map's record
    (see ``align_transitions``) with both coordinate systems added.
    """
    for name, coords, batch in (("source", source_coordinates, source), ("target", target_coordinates, target)):
        if not isinstance(coords, Coordinates):
            raise ValueError(f"{name}_coordinates must be Coordinates, got {type(coords).__name__}")
        if isinstance(batch, Transitions) and batch.state_dim != coords.dim:
            raise ValueError(
                f"{name}_coordinates cover {coords.dim} coordinates but {name} states have {batch.state_dim}"
            )
    step: SourceStep | None = None if source_step is None else source_coordinates.step(source_step)
    inner, record = align_transitions(
        source_coordinates.transitions(source),
        target_coordinates.transitions(target),
        n_source_actions,
        n_target_actions,
        source_periodic=source_coordinates.periodic,
        target_periodic=target_coordinates.periodic,
        source_step=step,
        settings=settings,
        rng=rng,
    )
    record = dict(
        record,
        source_coordinates=dataclasses.asdict(source_coordinates),
        target_coordinates=dataclasses.asdict(target_coordinates),
    )
    return InCoordinates(inner, source_coordinates, target_coordinates), record


__all__ = ["Coordinates", "InCoordinates", "align_in_coordinates"]
