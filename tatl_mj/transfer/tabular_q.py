"""Exact Q-iteration on a known deterministic tabular model, and the Q table it returns.

The paper solves the grid-world source by Q-Iteration (Phase I with a known model:
``source_learning.method = "q_iteration"``), and ``ta-tl-replan`` plans by it on
its merged model (``tatl_mj.transfer.tabular``). :class:`TabularQ` is a
``QFunction`` (``tatl_mj.transfer.fqi``) over state indices or grid cells.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from tatl_mj.transfer.features import as_states


@dataclasses.dataclass(frozen=True, eq=False)
class TabularQ:
    """Q as a table q (S, n_actions).

    ``values``/``greedy`` take either (N,) integer state indices, or (N, 2)
    ``[row, col]`` cells when ``cells`` (S, 2), the cell of each index (the grid
    world's ``cells`` array), was given. A cell not in ``cells`` raises ValueError.
    """

    q: np.ndarray  # float64, kept as given
    cells: np.ndarray | None = None

    def __post_init__(self) -> None:
        q = self.q
        if not (isinstance(q, np.ndarray) and q.dtype == np.float64 and q.ndim == 2):
            raise ValueError(f"TabularQ.q must be a float64 array (S, n_actions), got {np.shape(q)} {type(q).__name__}")
        if self.cells is not None:
            cells = np.asarray(self.cells)
            if cells.shape != (len(q), 2) or np.any(cells != np.rint(cells)) or cells.min() < 0:
                raise ValueError(f"TabularQ.cells must be ({len(q)}, 2) non-negative integers [row, col]")
            object.__setattr__(self, "cells", cells.astype(np.int64))

    @functools.cached_property
    def _lookup(self) -> np.ndarray:
        """[row, col] -> state index over the cells' bounding box (-1: no cell); needs ``cells``."""
        cells = self.cells
        assert cells is not None
        lookup = np.full((cells[:, 0].max() + 1, cells[:, 1].max() + 1), -1, dtype=np.int64)
        lookup[cells[:, 0], cells[:, 1]] = np.arange(len(cells))
        return lookup

    @property
    def n_actions(self) -> int:
        return self.q.shape[1]

    def index(self, states: np.ndarray) -> np.ndarray:
        """State indices (N,) from indices (N,) or [row, col] cells (N, 2)."""
        s = np.asarray(states)
        if s.ndim == 1:
            idx = s.astype(np.int64)
            if np.any(idx != s) or np.any((idx < 0) | (idx >= len(self.q))):
                raise ValueError(f"TabularQ state indices must be integers in 0..{len(self.q) - 1}")
            return idx
        if self.cells is None:
            raise ValueError("TabularQ got [row, col] states but was built without cells; pass indices")
        if s.shape == (1, 2):  # a policy stepped one cell a call: the same index, without array checks
            row, col = float(s[0, 0]), float(s[0, 1])
            r, c = round(row), round(col)  # half to even, as np.rint
            shape = self._lookup.shape
            if abs(row - r) <= 1e-9 and abs(col - c) <= 1e-9 and 0 <= r < shape[0] and 0 <= c < shape[1]:
                found = int(self._lookup[r, c])
                if found >= 0:
                    return np.array([found], dtype=np.int64)
        rc = as_states(s, dim=2)
        cells = np.rint(rc).astype(np.int64)
        lookup = self._lookup
        inside = (
            (cells[:, 0] >= 0) & (cells[:, 0] < lookup.shape[0]) & (cells[:, 1] >= 0) & (cells[:, 1] < lookup.shape[1])
        )
        if (np.abs(rc - cells) > 1e-9).any() or not inside.all():  # methods: called one state at a time
            raise ValueError("TabularQ states must be [row, col] cells of the grid")
        idx = lookup[cells[:, 0], cells[:, 1]]
        if (idx < 0).any():
            raise ValueError(f"TabularQ states {cells[idx < 0][:3].tolist()} are not cells of the grid")
        return idx

    def values(self, states: np.ndarray) -> np.ndarray:
        return self.q[self.index(states)]

    def greedy(self, states: np.ndarray) -> np.ndarray:
        return np.argmax(self.values(states), axis=1).astype(np.int64)


def q_iteration(
    next_state: np.ndarray,
    reward: np.ndarray,
    absorbing: np.ndarray,
    gamma: float,
    tol: float = 1e-10,
    cells: np.ndarray | None = None,
) -> TabularQ:
    """Exact Q-iteration on a deterministic tabular model (Bellman optimality, to ``tol``).

    ``Q(s, a) = reward[s, a] + gamma * (1 - absorbing[s, a]) * max_b Q(next_state[s, a], b)``,
    iterated from 0 until the largest change is below ``tol`` (a gamma-contraction,
    so it converges for gamma < 1). ``cells`` (S, 2) lets the result take [row, col] states.
    """
    nxt = np.asarray(next_state)
    r = np.asarray(reward, dtype=np.float64)
    done = np.asarray(absorbing, dtype=bool)
    if nxt.ndim != 2 or r.shape != nxt.shape or done.shape != nxt.shape:
        raise ValueError(f"next_state, reward, absorbing must all be (S, A); got {nxt.shape}, {r.shape}, {done.shape}")
    if not np.all(np.isfinite(r)):
        raise ValueError("reward contains NaN or infinite values")
    if np.any(nxt != np.rint(nxt)) or nxt.min() < 0 or nxt.max() >= len(nxt):
        raise ValueError(f"next_state must hold state indices in 0..{len(nxt) - 1}")
    if not (isinstance(gamma, (int, float)) and 0.0 <= gamma < 1.0):
        raise ValueError(f"gamma must be in [0, 1), got {gamma!r}")
    if not tol > 0:
        raise ValueError(f"tol must be > 0, got {tol!r}")
    nxt = nxt.astype(np.int64)
    continues = gamma * (~done)
    # Contraction bound: |Q_k - Q*| <= gamma^k |r|_max / (1 - gamma).
    bound = np.abs(r).max() / (1.0 - gamma) if gamma > 0 else 0.0
    limit = 1 + (math.ceil(math.log(tol / bound) / math.log(gamma)) if gamma > 0 and bound > tol else 1)
    q = np.zeros_like(r)
    for _ in range(limit + 10):
        new = r + continues * q.max(axis=1)[nxt]
        change = np.abs(new - q).max()
        q = new
        if change < tol:
            break
    return TabularQ(q, cells)


__all__ = ["TabularQ", "q_iteration"]
