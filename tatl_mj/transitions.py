"""A batch of transitions (s, a, r, s', absorbing): what every learner in tatl-mj eats.

Arrays are contiguous and typed (no per-step Python objects), so 10^6
cart-pole transitions take about 90 MB.
"""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class Transitions:
    """``n`` transitions of a task, in the paper's state coordinates.

    Attributes:
      states: (n, d) float64, s_i.
      actions: (n,) int64, index of a_i in the domain's discrete action set.
      rewards: (n,) float64, r_i.
      next_states: (n, d) float64, s_{i+1}.
      absorbing: (n,) bool, True where s_{i+1} ends the episode with discount 0
        (a failure or the goal), so no value is bootstrapped from it. A time
        limit is not absorbing.
      last: (n,) bool, True where the episode (or the collected segment) ends
        after this transition, absorbing or not.
    """

    states: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    next_states: np.ndarray
    absorbing: np.ndarray
    last: np.ndarray

    def __post_init__(self) -> None:
        cast = {
            "states": np.float64,
            "actions": np.int64,
            "rewards": np.float64,
            "next_states": np.float64,
            "absorbing": np.bool_,
            "last": np.bool_,
        }
        for name, dtype in cast.items():
            object.__setattr__(self, name, np.ascontiguousarray(getattr(self, name), dtype=dtype))
        n = len(self.states)
        if self.states.ndim != 2:
            raise ValueError(f"Transitions.states must be 2-D (n, d), got shape {self.states.shape}")
        if self.next_states.shape != self.states.shape:
            raise ValueError(
                f"Transitions.next_states shape {self.next_states.shape} != states shape {self.states.shape}"
            )
        for name in ("actions", "rewards", "absorbing", "last"):
            if getattr(self, name).shape != (n,):
                raise ValueError(f"Transitions.{name} must have shape ({n},), got {getattr(self, name).shape}")
        for name in ("states", "rewards", "next_states"):
            if not np.all(np.isfinite(getattr(self, name))):
                raise ValueError(f"Transitions.{name} contains NaN or infinite values")

    def __len__(self) -> int:
        return len(self.states)

    @property
    def state_dim(self) -> int:
        return self.states.shape[1]

    def head(self, n: int) -> "Transitions":
        """The first ``n`` transitions (a budget of ``n`` target samples)."""
        if not 0 <= n <= len(self):
            raise ValueError(f"cannot take {n} of {len(self)} transitions")
        return Transitions(*(getattr(self, f.name)[:n] for f in dataclasses.fields(self)))

    @staticmethod
    def concatenate(parts: "list[Transitions]") -> "Transitions":
        if not parts:
            raise ValueError("cannot concatenate an empty list of Transitions")
        return Transitions(
            *(np.concatenate([getattr(p, f.name) for p in parts]) for f in dataclasses.fields(Transitions))
        )

    def save(self, path: str) -> None:
        np.savez(path, **{f.name: getattr(self, f.name) for f in dataclasses.fields(self)})

    @staticmethod
    def load(path: str) -> "Transitions":
        with np.load(path) as data:
            return Transitions(**{f.name: data[f.name] for f in dataclasses.fields(Transitions)})
