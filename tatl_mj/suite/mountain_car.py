"""Placeholder until the mountain_car domain lands (being written now)."""

import numpy as np

ACTIONS = np.zeros((0, 1))
TASKS: dict = {}
