"""What policies and queries hand the sampler, checked with messages that name what is wrong."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from tatl_mj.sampling.simulator import Simulator

IndexPolicy = Callable[[np.ndarray], np.ndarray]
"""``policy(states (N, d)) -> (N,)`` indices into the domain's ``ACTIONS``."""

ValuePolicy = Callable[[np.ndarray], np.ndarray]
"""``policy(states (N, d)) -> (N, action_dim)`` action values in actuator units."""


@runtime_checkable
class DrawingPolicy(Protocol):
    """An index policy whose random draws do not depend on the states it is asked about.

    ``draws(calls)`` draws now, one row a call, what its next ``calls`` calls on one
    state each would draw; ``act(states, draws)`` answers such calls for every row
    of ``states`` at once, row i having drawn ``draws[i]``: the indices that the
    one-state calls return. Episodes of one environment can then run in lockstep.
    """

    def __call__(self, states: np.ndarray) -> np.ndarray: ...

    def draws(self, calls: int) -> np.ndarray: ...

    def act(self, states: np.ndarray, draws: np.ndarray) -> np.ndarray: ...


def check_indices(indices: Any, n: int, n_actions: int) -> np.ndarray:
    a = np.asarray(indices)
    if a.shape != (n,) or a.dtype.kind not in "iu":  # signed or unsigned integers
        raise ValueError(f"policy must return ({n},) integer action indices, got {a.dtype} {a.shape}")
    # One state a call in the environment loops: a scalar comparison, not two reductions.
    low, high = (a[0], a[0]) if n == 1 else (a.min(), a.max()) if n else (0, 0)
    if low < 0 or high >= n_actions:
        raise ValueError(f"action indices must be in 0..{n_actions - 1}, got {low}..{high}")
    return a.astype(np.int64, copy=False)


def check_values(values: Any, n: int, sim: Simulator) -> np.ndarray:
    v = np.asarray(values, np.float64)
    if v.shape == (n,) and sim.action_dim == 1:
        v = v[:, None]
    if v.shape != (n, sim.action_dim):
        if np.issubdtype(sim.actions.dtype, np.integer):  # the task takes action indices
            raise ValueError(
                f"policy must return ({n},) action indices in 0..{len(sim.actions) - 1} "
                f"for {sim.domain}, got shape {v.shape}"
            )
        raise ValueError(f"policy must return ({n}, {sim.action_dim}) action values, got {v.shape}")
    return v


def check_states(states: Any) -> np.ndarray:
    s = np.asarray(states, np.float64)
    if s.ndim != 2 or not np.all(np.isfinite(s)):
        raise ValueError(f"states must be a finite (N, d) array, got shape {s.shape}")
    return s
