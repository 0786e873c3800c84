"""A user's own transfer method, as `tatl run --methods plugin_method:ZeroTorque` loads it."""

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class ZeroTorque:
    """Ignores the source entirely: always the middle action (no torque)."""

    name: str = "zero"

    def learn(self, problem, target_samples):
        middle = np.asarray(problem.target_actions, dtype=np.float64)[len(problem.target_actions) // 2]
        return lambda states: np.repeat(middle[None], len(states), axis=0)
