"""Placeholder until the cartpole domain lands (being written now)."""

import numpy as np

ACTIONS = np.zeros((0, 1))
TASKS: dict = {}
