"""Tabular models of a discrete target: the counting apprentice ``ta-tl-replan`` plans on.

The methods themselves (``ta-tl-replan``, ``ta-tl-oracle``) are in
``tatl_mj.transfer.methods.replan``; this module holds their building blocks.

For a target whose states are cells of a finite set (integer-valued state vectors,
listed in a :class:`CellMap`) and whose actions are indices, the control-affine
apprentice ``s' = W phi(s) + B a`` cannot represent walls and wind at once, and
Algorithm 1's one-step rule is itself the limit: it picks the target action whose
predicted next state lands nearest the projected source next state
``chi(P_S(chi_plus(s), pi*_S))``. With unit moves no single move need cancel a
push, so even the exact target model can send the agent back and forth between
two cells (``methods.replan.OneStepRule`` with the exact model shows it; the diagnosis
measured 2.4 of a possible 10 on the windy grid).

``ta-tl-replan`` departs from Algorithm 1 on purpose. Instead of tracking the
source trajectory one step at a time it replans:

1. ``P_hat_T``: :class:`TabularApprentice` counts next cells per (cell, action)
   in the target samples and predicts the most frequent one (a deterministic
   model); the reward and absorbing flag of a visited pair are those the target
   paid on the samples that landed there.
2. Where a pair was never visited, the apprentice falls back to a prior model:
   the source model carried through the mapping (:func:`mapped_model`; for the
   identity mapping, the source's own table), or, for the ablation without the
   source prior, :func:`uninformed_model` (stay in place, reward 0). By default
   (``prior_scope="agreeing-cells"``) the source prior is trusted only in cells
   whose visited pairs all agree with it; the unvisited pairs of a cell where the
   target was seen to differ stay in place with reward 0. Why: a batch policy
   cannot correct itself, and an unvisited source move that the target turns
   aside (the wind blowing the agent back off the goal) traps it in a loop. On
   the windy grid this raised the final return at 5000 random samples from
   9.0-9.4 to 9.9-10 (3 seeds), and the returns at 500-2000 samples too. With
   the paper's protocol data (the source policy from random starts, about one
   action per cell) it discards the prior almost everywhere and fails (returns
   -27 to -6); use ``prior_scope="unvisited"`` there (9.0-10 from 100 starts).
3. ``methods.replan.replan`` runs exact Q-iteration on that merged model and acts greedily
   (:class:`ReplanPolicy`).

Why the target's reward on visited pairs and not the source's: the source's
reward table is indexed by (cell, action), so where the target moves the agent
elsewhere it would still pay the source's outcome (e.g. the goal bonus of a move
the wind turns aside) and the planner would chase it. With the target's own
outcome, the exact target model makes the planner return the target's optimal
values exactly (tests/test_transfer_tabular.py). Unvisited pairs keep the
source's reward and absorbing flag with the source's next cell: the source
outcome as a whole is the prior.

Nothing here knows a particular domain: a domain provides its known model as
``(next_state, reward, absorbing, cells)`` tables (:class:`TabularModel` and
:class:`CellMap`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from tatl_mj.description import CellMap
from tatl_mj.transfer.intertask_mapping import Mapping
from tatl_mj.transfer.tabular_q import TabularQ, q_iteration
from tatl_mj.transitions import Transitions
from tatl_mj.validation import integer

PRIOR_SCOPES = ("agreeing-cells", "unvisited")
"""Where a :class:`TabularApprentice` uses its fallback for unvisited pairs."""


# --- Cells and models -------------------------------------------------------------


@dataclasses.dataclass(frozen=True, eq=False)
class TabularModel:
    """A deterministic model over cell indices, as exact Q-iteration takes it.

    Attributes (numpy arrays, checked and kept as given):
      next_state: (S, A) integer next cell of each (cell, action).
      reward: (S, A) real.
      absorbing: (S, A) bool, True where the step ends the episode with discount 0.
    """

    next_state: np.ndarray
    reward: np.ndarray
    absorbing: np.ndarray

    def __post_init__(self) -> None:
        nxt, r, done = self.next_state, self.reward, self.absorbing
        if not all(isinstance(x, np.ndarray) for x in (nxt, r, done)):
            raise ValueError(
                "TabularModel next_state, reward, absorbing must be numpy arrays, got "
                f"{type(nxt).__name__}, {type(r).__name__}, {type(done).__name__}"
            )
        if nxt.ndim != 2 or r.shape != nxt.shape or done.shape != nxt.shape:
            raise ValueError(
                f"TabularModel next_state, reward, absorbing must all be (S, A); "
                f"got {nxt.shape}, {r.shape}, {done.shape}"
            )
        if done.dtype != np.bool_:
            raise ValueError(f"TabularModel.absorbing must be bool, got {done.dtype}")
        if not (np.issubdtype(r.dtype, np.integer) or np.issubdtype(r.dtype, np.floating)):
            raise ValueError(f"TabularModel.reward must be numbers, got {r.dtype}")
        if not np.all(np.isfinite(r)):
            raise ValueError("TabularModel.reward contains NaN or infinite values")
        if not np.issubdtype(nxt.dtype, np.integer) or nxt.min() < 0 or nxt.max() >= len(nxt):
            raise ValueError(f"TabularModel.next_state must hold cell indices in 0..{len(nxt) - 1}")

    @property
    def n_cells(self) -> int:
        return self.next_state.shape[0]

    @property
    def n_actions(self) -> int:
        return self.next_state.shape[1]

    def q(self, gamma: float, tol: float = 1e-10) -> TabularQ:
        """Exact Q-iteration on this model (``tabular_q.q_iteration``), over cell indices."""
        return q_iteration(self.next_state, self.reward, self.absorbing, gamma, tol)


def uninformed_model(n_cells: int, n_actions: int) -> TabularModel:
    """The prior of the ablation without the source: every pair stays in place, reward 0.

    Why this one: it claims nothing about the target. An unvisited pair is worth
    ``gamma V(s)`` (waiting), so the planner prefers any known route to reward
    and never invents one through unseen pairs.
    """
    for name, value in (("n_cells", n_cells), ("n_actions", n_actions)):
        integer("", name, value, 1)
    stay = np.repeat(np.arange(n_cells, dtype=np.int64)[:, None], n_actions, axis=1)
    return TabularModel(stay, np.zeros((n_cells, n_actions)), np.zeros((n_cells, n_actions), dtype=bool))


def mapped_model(source: TabularModel, source_cells: CellMap, target_cells: CellMap, mapping: Mapping) -> TabularModel:
    """The source model carried to the target's cells through chi / chi_plus.

    Target cell c stands for the source cell nearest ``chi_plus(c)``; its action a
    leads to the target cell nearest ``chi(next source cell)``, with the source's
    reward and absorbing flag. With the identity mapping and the same cells this
    is the source model itself.
    """
    if source.n_cells != source_cells.n_cells:
        raise ValueError(f"source model has {source.n_cells} cells, source_cells has {source_cells.n_cells}")
    s_of_t = source_cells.nearest(mapping.chi_plus(target_cells.cells.astype(np.float64)))
    t_of_s = target_cells.nearest(mapping.chi(source_cells.cells.astype(np.float64)))
    return TabularModel(
        t_of_s[source.next_state[s_of_t]],
        source.reward[s_of_t],
        source.absorbing[s_of_t],
    )


# --- The tabular apprentice -------------------------------------------------------


@dataclasses.dataclass(frozen=True, eq=False)
class TabularApprentice:
    """P_hat_T by counting: the most frequent next cell of each visited (cell, action).

    Attributes:
      counts: (S, A, S) int64, how often (cell, action) led to each next cell.
      reward_sum: (S, A, S) float64, the rewards of those transitions, summed.
      absorbing_count: (S, A, S) int64, how many of them ended the episode.
      fallback: the model used for unvisited pairs (:func:`mapped_model` of the
        source, or :func:`uninformed_model`).
      prior_scope: ``"agreeing-cells"`` (default): an unvisited pair takes the
        fallback only if every visited pair of its cell agrees with the fallback
        (same next cell, reward and absorbing flag; a cell without data agrees),
        else it stays in place with reward 0. ``"unvisited"``: every unvisited
        pair takes the fallback.

    Prediction for a visited pair: the next cell with the most counts; on a tie
    the fallback's next cell if it is among the tied ones, else the lowest cell
    index. Its reward is the mean of the rewards of the samples that landed on
    that cell, and it is absorbing when at least half of them were.
    """

    counts: np.ndarray
    reward_sum: np.ndarray
    absorbing_count: np.ndarray
    fallback: TabularModel
    prior_scope: str = "agreeing-cells"

    def __post_init__(self) -> None:
        if self.prior_scope not in PRIOR_SCOPES:
            raise ValueError(f"TabularApprentice.prior_scope must be one of {PRIOR_SCOPES}, got {self.prior_scope!r}")
        if not isinstance(self.fallback, TabularModel):
            raise ValueError(f"TabularApprentice.fallback must be a TabularModel, got {type(self.fallback).__name__}")
        shape = (self.fallback.n_cells, self.fallback.n_actions, self.fallback.n_cells)
        for name in ("counts", "reward_sum", "absorbing_count"):
            if np.shape(getattr(self, name)) != shape:
                raise ValueError(f"TabularApprentice.{name} must be {shape}, got {np.shape(getattr(self, name))}")

    @property
    def n_cells(self) -> int:
        return self.fallback.n_cells

    @property
    def n_actions(self) -> int:
        return self.fallback.n_actions

    @property
    def visited(self) -> np.ndarray:
        """(S, A) bool: the pairs seen at least once in the target samples."""
        return self.counts.sum(axis=2) > 0

    def model(self) -> TabularModel:
        """The merged model: the apprentice on visited pairs, the fallback elsewhere."""
        best = self.counts.max(axis=2, keepdims=True)
        tied = (self.counts == best) & (best > 0)
        cell, action = np.indices((self.n_cells, self.n_actions))
        prior = self.fallback.next_state
        nxt = np.where(tied[cell, action, prior], prior, np.argmax(tied, axis=2))
        n = self.counts[cell, action, nxt]
        visited = n > 0
        safe = np.maximum(n, 1)
        seen_reward = self.reward_sum[cell, action, nxt] / safe
        seen_absorbing = 2 * self.absorbing_count[cell, action, nxt] >= n
        fb = self.fallback
        if self.prior_scope == "agreeing-cells":
            differs = visited & ((nxt != fb.next_state) | (seen_reward != fb.reward) | (seen_absorbing != fb.absorbing))
            distrusted = differs.any(axis=1, keepdims=True) & ~visited
            fb = TabularModel(
                np.where(distrusted, cell, fb.next_state),
                np.where(distrusted, 0.0, fb.reward),
                fb.absorbing & ~distrusted,
            )
        return TabularModel(
            np.where(visited, nxt, fb.next_state),
            np.where(visited, seen_reward, fb.reward),
            np.where(visited, seen_absorbing, fb.absorbing),
        )

    def predict(self, cells: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """(N,) cell indices, (N,) action indices -> (N,) predicted next cell indices."""
        c, a = np.asarray(cells), np.asarray(actions)
        if c.shape != a.shape or c.ndim != 1:
            raise ValueError(f"cells and actions must be (N,) arrays of one length, got {c.shape} and {a.shape}")
        if len(c) and (c.min() < 0 or c.max() >= self.n_cells or a.min() < 0 or a.max() >= self.n_actions):
            raise ValueError(f"cells must be in 0..{self.n_cells - 1} and actions in 0..{self.n_actions - 1}")
        return self.model().next_state[c, a]


def fit_tabular_apprentice(
    samples: Transitions,
    cell_map: CellMap,
    fallback: TabularModel,
    prior_scope: str = "agreeing-cells",
) -> TabularApprentice:
    """Counts ``samples`` (states and next states must be cells of ``cell_map``);
    ``prior_scope`` as in :class:`TabularApprentice`."""
    if fallback.n_cells != cell_map.n_cells:
        raise ValueError(f"fallback has {fallback.n_cells} cells, cell_map has {cell_map.n_cells}")
    n_cells, n_actions = fallback.n_cells, fallback.n_actions
    shape = (n_cells, n_actions, n_cells)
    if len(samples) and (samples.actions.min() < 0 or samples.actions.max() >= n_actions):
        raise ValueError(f"samples.actions must be in 0..{n_actions - 1}")
    flat = (
        np.ravel_multi_index(
            (cell_map.index(samples.states), samples.actions, cell_map.index(samples.next_states)), shape
        )
        if len(samples)
        else np.zeros(0, np.int64)
    )
    size = n_cells * n_actions * n_cells
    return TabularApprentice(
        counts=np.bincount(flat, minlength=size).reshape(shape).astype(np.int64),
        reward_sum=np.bincount(flat, weights=samples.rewards, minlength=size).reshape(shape),
        absorbing_count=np.bincount(flat, weights=samples.absorbing, minlength=size).reshape(shape).astype(np.int64),
        fallback=fallback,
        prior_scope=prior_scope,
    )


__all__ = [
    "PRIOR_SCOPES",
    "TabularApprentice",
    "TabularModel",
    "fit_tabular_apprentice",
    "mapped_model",
    "uninformed_model",
]
