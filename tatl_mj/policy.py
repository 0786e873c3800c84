"""What a sampler may assume of a policy it is handed, beyond its call."""

from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np


@dataclasses.dataclass(frozen=True, eq=False)
class StatePolicy:
    """A policy whose answer for a state depends on that state alone: no random
    draws, nothing kept between calls.

    A sampler stepping a task's known table may then ask it once per cell and
    reuse that answer, which is what a call every step would return.
    """

    policy: Callable[[np.ndarray], np.ndarray]

    def __call__(self, states: np.ndarray) -> np.ndarray:
        return self.policy(states)


__all__ = ["StatePolicy"]
