"""The inter-task mapping kinds (Phase II), by the names specs use: one table, ``MAPPINGS``.

Each kind maps to a builder that takes what the pipeline gathers for it
(:class:`MappingInputs`) and returns the mapping (in each task's mapping
coordinates), its record, and the source and target samples it used. The spec
loader takes its valid kinds from this table.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable

import numpy as np

from tatl_mj.description import TaskDescription
from tatl_mj.transfer import coordinates
from tatl_mj.transfer.intertask_mapping import AffineMapping, IdentityMapping
from tatl_mj.transfer.manifold_alignment import align_manifolds
from tatl_mj.transfer.transition_alignment import TransitionAlignment
from tatl_mj.transitions import Transitions

Built = tuple[Any, "dict | None", int, int]
"""A builder's result: the mapping, its record (or None), source and target samples used."""


@dataclasses.dataclass(frozen=True, eq=False)
class MappingInputs:
    """What a mapping kind may be built from.

    Attributes:
      settings: the spec's ``[mapping]`` table (``spec.MappingSpec``).
      source, target: the two tasks' descriptions.
      n: how many samples of each task a learned map aligns (the preset's).
      source_samples: ``source_samples(n)`` -> n source transitions for a learned map.
      target_stream: the target's shared stream, whose head a learned map uses.
      rng: ``rng()`` -> the generator a learned map draws from.
    """

    settings: Any
    source: TaskDescription
    target: TaskDescription
    n: int
    source_samples: Callable[[int], Transitions]
    target_stream: Transitions
    rng: Callable[[], np.random.Generator]

    def coordinates(self) -> tuple[coordinates.Coordinates, coordinates.Coordinates]:
        """Each task's mapping coordinates (its periodic coordinates from their origin)."""
        source, target = self.source, self.target
        return (
            coordinates.Coordinates(source.periodic, source.angle_origin),
            coordinates.Coordinates(target.periodic, target.angle_origin),
        )


def identity(inputs: MappingInputs) -> Built:
    """chi = chi_plus = the identity (equal state spaces)."""
    return IdentityMapping(), None, 0, 0


def affine(inputs: MappingInputs) -> Built:
    """A hand-coded chi(s_S) = matrix s_S + offset, in each task's mapping coordinates."""
    source_coords, target_coords = inputs.coordinates()
    settings = inputs.settings
    matrix = np.asarray(settings.matrix, dtype=np.float64)  # its shape is checked at spec load
    offset = np.asarray(settings.offset or np.zeros(len(matrix)), dtype=np.float64)
    record = {"kind": "affine", "matrix": matrix.tolist(), "offset": offset.tolist()}
    inner = AffineMapping(matrix, offset)
    return coordinates.InCoordinates(inner, source_coords, target_coords), record, 0, 0


def transition_settings(table: dict) -> TransitionAlignment:
    """A spec's ``mapping.transition`` table as settings (TOML arrays as tuples)."""
    return TransitionAlignment.from_dict({k: tuple(v) if isinstance(v, list) else v for k, v in table.items()})


def transition_alignment(inputs: MappingInputs) -> Built:
    """The map whose candidates best explain the target's transitions (``TransitionAlignment``)."""
    source_coords, target_coords = inputs.coordinates()
    source, target = inputs.source_samples(inputs.n), inputs.target_stream.head(inputs.n)
    rng = inputs.rng()
    mapping, record = coordinates.align_in_coordinates(
        source,
        target,
        source_coords,
        target_coords,
        inputs.source.n_actions,
        inputs.target.n_actions,
        settings=transition_settings(inputs.settings.transition),
        rng=rng,
    )
    return mapping, record, len(source), len(target)


def manifold_alignment(inputs: MappingInputs) -> Built:
    """The paper's map, learned without supervision from both tasks' states."""
    source_coords, target_coords = inputs.coordinates()
    source, target = inputs.source_samples(inputs.n), inputs.target_stream.head(inputs.n)
    rng = inputs.rng()
    inner = align_manifolds(
        source_coords.to_mapping(source.states),
        target_coords.to_mapping(target.states),
        n_neighbors=inputs.settings.n_neighbors,
        mu=inputs.settings.mu,
        rng=rng,
    )
    return coordinates.InCoordinates(inner, source_coords, target_coords), None, len(source), len(target)


MAPPINGS: dict[str, Callable[[MappingInputs], Built]] = {
    "identity": identity,
    "manifold_alignment": manifold_alignment,
    "transition_alignment": transition_alignment,
    "affine": affine,
}
"""Mapping kinds: name -> builder(inputs)."""


__all__ = ["MAPPINGS", "MappingInputs", "affine", "identity", "manifold_alignment", "transition_alignment"]
