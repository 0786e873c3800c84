"""What a task is, as transfer methods see it, without stepping anything.

Every suite domain provides ``describe(task, **task_kwargs) -> TaskDescription``
(``tatl_mj.suite.describe`` dispatches), so the experiment pipeline, the
sampler, the renderer and transfer methods never special-case a domain by
name: the grid world's moves, its known model, the pendulum's periodic angle
and the mountain car's settable track all come from here.

Pure numpy: ``tatl_mj.transfer`` imports it without importing mujoco.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Callable

import numpy as np

KnownModel = Callable[[], tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]
"""A deterministic tabular model: () -> (next_state (S, A) int, reward (S, A), absorbing (S, A) bool,
cells (S, d) the state vector of each index)."""


def _floats(values, name: str, n: int | None = None) -> np.ndarray:
    a = np.asarray(values, dtype=np.float64)
    if n is not None and a.shape != (n,):
        raise ValueError(f"TaskDescription.{name} must have {n} entries, got shape {a.shape}")
    return a


@dataclasses.dataclass(frozen=True, eq=False)
class TaskDescription:
    """Static facts about one ``domain/task`` (with its task kwargs).

    Attributes:
      domain, task: the suite names.
      state_names: one name per entry of the paper's state vector (its size is ``state_dim``).
      periodic: per state entry, whether it is an angle wrapped to [-pi, pi).
      angle_origin: per state entry, where a mapping should measure a periodic
        coordinate from (e.g. the pendulum's hanging angle, pi, so that random
        data near hanging do not straddle the wrap); 0 elsewhere.
      action_values: (n, m) the paper's discrete action set as learners see it:
        actuator values, or for a ``discrete`` task the effect of each index
        (the grid world's moves [d_row, d_col]).
      discrete: the environment takes action indices, not actuator values.
      action_low, action_high: (m,) actuator limits (None for a discrete task).
      state_low, state_high: (d,) the range ``set_state_vector`` accepts
        (-inf/inf where unlimited); a source simulator is queried inside it.
      reset_low, reset_high: (d,) a finite box of states a simulator reset may place
        the system in, where its behaviour matters: the ``reset`` data protocol and
        model-based learners draw states uniformly from it. For a ``discrete`` task
        with a known model, its cells are drawn instead. None where not declared.
      control_timestep: seconds per control step (None where steps have no duration).
      known_model: the task's exact tabular model when it has one (else None).
      transition_reward, transition_absorbing: the task's reward of a step
        ``(states, action_indices, next_states) -> (N,)`` and its end condition
        ``next_states -> (N,) bool``, for a task whose reward is not a function of
        the next state alone (the grid world's bumps); a model standing in for the
        task (Algorithm 2) is scored with them. None where the task's own
        ``batch_reward`` serves.
      gymnasium_peer: the Gymnasium environment a user would otherwise pick for
        this task (``tatl bench`` times its loop beside ours), or None.
      steadiness: state entries whose root mean square over an evaluation
        episode's steps says how steadily a policy holds the task (the bicycle's
        roll); with them the evaluation also reports the mean absolute actuator
        value. Where episodes reach their cap, returns saturate and these do not.
      falls: an episode that ends before its cap has failed (the bicycle or the
        cart-pole fell), so survival to the cap says how well a policy holds it;
        False where an early end is a success (the grid world's goal) or none occurs.
      dynamics_version: the version of what the task computes (its physics, reward,
        end condition, start states, noise), bumped whenever a change could move a
        record; records and reference sets name it (docs/versions.md). Apart from
        the Gymnasium ids' interface version, which an action dtype also bumps.
    """

    domain: str
    task: str
    state_names: tuple[str, ...]
    periodic: tuple[bool, ...]
    action_values: np.ndarray
    discrete: bool
    control_timestep: float | None
    action_low: np.ndarray | None = None
    action_high: np.ndarray | None = None
    angle_origin: tuple[float, ...] | None = None
    state_low: np.ndarray | None = None
    state_high: np.ndarray | None = None
    reset_low: np.ndarray | None = None
    reset_high: np.ndarray | None = None
    known_model: KnownModel | None = None
    transition_reward: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None = None
    transition_absorbing: Callable[[np.ndarray], np.ndarray] | None = None
    gymnasium_peer: str | None = None
    steadiness: tuple[str, ...] = ()
    falls: bool = False
    dynamics_version: int = 1

    def __post_init__(self) -> None:
        if isinstance(self.dynamics_version, bool) or not isinstance(self.dynamics_version, int):
            raise ValueError(f"TaskDescription.dynamics_version must be a whole number, got {self.dynamics_version!r}")
        if self.dynamics_version < 1:
            raise ValueError(f"TaskDescription.dynamics_version must be >= 1, got {self.dynamics_version}")
        d = len(self.state_names)
        unknown = [n for n in self.steadiness if n not in self.state_names]
        if unknown:
            raise ValueError(f"TaskDescription.steadiness names {unknown}, not states; valid: {list(self.state_names)}")
        if len(self.periodic) != d:
            raise ValueError(f"TaskDescription.periodic must have {d} entries, got {len(self.periodic)}")
        actions = np.asarray(self.action_values, dtype=np.float64)
        actions = actions[:, None] if actions.ndim == 1 else actions
        object.__setattr__(self, "action_values", actions)
        origin = (0.0,) * d if self.angle_origin is None else tuple(float(v) for v in self.angle_origin)
        if len(origin) != d or any(o != 0 and not p for o, p in zip(origin, self.periodic)):
            raise ValueError(f"TaskDescription.angle_origin must have {d} entries, non-zero only where periodic")
        object.__setattr__(self, "angle_origin", origin)
        low = _floats(-np.inf * np.ones(d) if self.state_low is None else self.state_low, "state_low", d)
        high = _floats(np.inf * np.ones(d) if self.state_high is None else self.state_high, "state_high", d)
        object.__setattr__(self, "state_low", low)
        object.__setattr__(self, "state_high", high)
        if (self.reset_low is None) != (self.reset_high is None):
            raise ValueError("TaskDescription.reset_low and reset_high are given together or not at all")
        if self.reset_low is not None:
            box_low, box_high = _floats(self.reset_low, "reset_low", d), _floats(self.reset_high, "reset_high", d)
            if not (np.all(np.isfinite(box_low)) and np.all(np.isfinite(box_high)) and np.all(box_low < box_high)):
                raise ValueError("TaskDescription.reset_low < reset_high must be finite in every entry")
            object.__setattr__(self, "reset_low", box_low)
            object.__setattr__(self, "reset_high", box_high)
        if not self.discrete:
            m = actions.shape[1]
            if self.action_low is None or self.action_high is None:
                raise ValueError("TaskDescription.action_low/action_high are required for a continuous task")
            object.__setattr__(self, "action_low", _floats(self.action_low, "action_low", m))
            object.__setattr__(self, "action_high", _floats(self.action_high, "action_high", m))
        if self.control_timestep is not None and not (
            math.isfinite(self.control_timestep) and self.control_timestep > 0
        ):
            raise ValueError(f"TaskDescription.control_timestep must be > 0 s, got {self.control_timestep!r}")

    @property
    def state_dim(self) -> int:
        return len(self.state_names)

    @property
    def n_actions(self) -> int:
        return len(self.action_values)

    @property
    def action_dim(self) -> int:
        return self.action_values.shape[1]

    def reset_states(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` states spread over the reset box (uniform; a known model's cells for a discrete task)."""
        if self.discrete and self.known_model is not None:
            cells = np.asarray(self.known_model()[3], dtype=np.float64)
            return cells[rng.integers(len(cells), size=n)]
        if self.reset_low is None or self.reset_high is None:
            raise ValueError(f"{self.domain}/{self.task} declares no reset box (reset_low/reset_high)")
        return rng.uniform(self.reset_low, self.reset_high, size=(n, self.state_dim))

    def clip_to_settable(self, states: np.ndarray) -> np.ndarray:
        """``states`` moved to the nearest state ``set_state_vector`` accepts."""
        return np.clip(states, self.state_low, self.state_high)


@dataclasses.dataclass(frozen=True, eq=False)
class CellMap:
    """The cells of a discrete state space: state vector <-> cell index.

    Attributes:
      cells: (S, d) integer-valued state vectors; row i is cell i.
    """

    cells: np.ndarray

    def __post_init__(self) -> None:
        c = np.asarray(self.cells, dtype=np.float64)
        if c.ndim != 2 or len(c) == 0 or not np.all(np.isfinite(c)) or np.any(c != np.rint(c)):
            raise ValueError(f"CellMap.cells must be a non-empty (S, d) array of integers, got shape {c.shape}")
        cells = c.astype(np.int64)
        if len(np.unique(cells, axis=0)) != len(cells):
            raise ValueError("CellMap.cells must not repeat a cell")
        object.__setattr__(self, "cells", cells)  # frozen: the integer cells derived from the input

    @functools.cached_property
    def _low(self) -> np.ndarray:
        return self.cells.min(axis=0)

    @functools.cached_property
    def _lookup(self) -> np.ndarray:
        """A dense lookup over the cells' bounding box: state -> index in one fancy-index (-1: no cell)."""
        lookup = np.full(tuple(self.cells.max(axis=0) - self._low + 1), -1, dtype=np.int64)
        lookup[tuple((self.cells - self._low).T)] = np.arange(len(self.cells))
        return lookup

    @property
    def n_cells(self) -> int:
        return len(self.cells)

    @property
    def state_dim(self) -> int:
        return self.cells.shape[1]

    def index(self, states: np.ndarray) -> np.ndarray:
        """(N, d) states -> (N,) int64 cell indices; ValueError names a state that is no cell."""
        s = _as_states(states, "states", self.state_dim)
        rounded = np.rint(s).astype(np.int64)
        offset = rounded - self._low
        inside = np.all(rounded == s, axis=1) & np.all((offset >= 0) & (offset < self._lookup.shape), axis=1)
        idx = np.full(len(s), -1, dtype=np.int64)
        idx[inside] = self._lookup[tuple(offset[inside].T)]
        if np.any(idx < 0):
            raise ValueError(f"state {s[idx < 0][0].tolist()} is not one of the {self.n_cells} cells")
        return idx

    def nearest(self, points: np.ndarray) -> np.ndarray:
        """(N, d) points -> (N,) index of the nearest cell (Euclidean; lowest index on ties)."""
        p = _as_states(points, "points", self.state_dim)
        return np.argmin(np.sum((p[:, None, :] - self.cells[None, :, :]) ** 2, axis=2), axis=1).astype(np.int64)


def _as_states(states, name: str, dim: int) -> np.ndarray:
    s = np.asarray(states, dtype=np.float64)
    s = s.reshape(1, -1) if s.ndim == 1 else s
    if s.ndim != 2 or s.shape[1] != dim or not np.all(np.isfinite(s)):
        raise ValueError(f"{name} must be a finite (N, {dim}) array, got shape {np.shape(states)}")
    return s


__all__ = ["CellMap", "KnownModel", "TaskDescription"]
