"""A user's own transfer method, as `tatl run --methods plugin_method:ZeroTorque` loads it."""

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class ZeroTorque:
    """Ignores the source entirely: always the middle action (no torque or force on physics targets)."""

    name: str = "zero"

    def learn(self, problem, target_samples):
        middle = len(problem.target_actions) // 2
        if problem.target_discrete:  # the grid world: a policy returns action indices
            return lambda states: np.full(len(states), middle)
        value = np.asarray(problem.target_actions, dtype=np.float64)[middle]
        return lambda states: np.repeat(value[None], len(states), axis=0)
