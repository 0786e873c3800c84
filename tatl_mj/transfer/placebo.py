"""The placebo source: an untrained source Q of the trained one's shape.

A transfer method run on it keeps everything but the source's content (the
mapping, the controller, the apprentice, Algorithm 2), so comparing the method
with its placebo says whether what the source learned does the work, or only the
machinery around it. The placebo's parameters are drawn i.i.d. normal with the
trained parameters' mean and spread (so values, and UMA-TL's Q_0, are on the
trained scale), from a Generator seeded by the caller: reproducible per seed.
"""

from __future__ import annotations

import numpy as np

from tatl_mj.transfer.fqi import LinearQ, QFunction
from tatl_mj.transfer.tabular_q import TabularQ

SOURCES = ("trained", "placebo")
"""A method's ``source`` setting: the source Q learned in Phase I, or its placebo."""


def _like(values: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return values.mean() + values.std() * rng.standard_normal(values.shape)


def placebo_q(trained: QFunction, seed: int) -> QFunction:
    """An untrained Q with ``trained``'s basis (or table shape), drawn from ``seed``."""
    rng = np.random.default_rng(seed)
    if isinstance(trained, LinearQ):
        return LinearQ(trained.features, _like(trained.weights, rng))
    if isinstance(trained, TabularQ):
        return TabularQ(_like(trained.q, rng), trained.cells)
    raise ValueError(
        f"a placebo source needs a linear or tabular source Q, got {type(trained).__name__}; "
        "use a linear source learner (regressor = 'linear') or q_iteration"
    )
