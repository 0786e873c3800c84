"""Fitted Q-Iteration (Ernst, Geurts & Wehenkel 2005): the paper's Phase I and the RL baseline.

Given a batch of transitions (s_i, a_i, r_i, s'_i, absorbing_i) with discrete actions,
FQI repeats for k = 1..K

    y_i = r_i + gamma * (1 - absorbing_i) * max_a Q_{k-1}(s'_i, a),     Q_k = fit((s_i, a_i) -> y_i)

from Q_0 = 0 or from a given ``initial_q`` (UMA-TL starts from the mapped source Q).
With a ``prior_q`` the regressor fits the residual instead, ``Q_k = prior_q + fit(y - prior_q)``,
so the prior stays in every iterate (``uma-tl-prior``: the mapped source Q can then
mislead every fit, and negative transfer can show).
Two regressors are provided:

- :class:`LinearRegressor`: ``Q(s, a) = w_a . phi(s)`` (the paper's single layer of RBF or
  linear bases), one ridge least-squares problem per action. The Gram matrices do not
  change between iterations, so each is factorised once and an iteration costs two
  passes over precomputed features and a few triangular solves; when next states
  repeat (a grid), an iteration runs on the empirical model instead, which for one-hot
  features is Q-iteration on the counted model (same weights up to rounding);
- :class:`ExtraTrees`: scikit-learn's extremely randomised trees on the input
  ``(s, a)`` as in Ernst et al. (50 trees, min_samples_split 5, min_samples_leaf 2).

Exact Q-iteration on a known tabular model (the grid-world source, which the paper
solves by Q-Iteration) is ``tatl_mj.transfer.tabular_q``; the seconds this process
spends in :func:`fitted_q_iteration` are metered by ``tatl_mj.transfer.fit_time``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any, Callable, Protocol, runtime_checkable

import numpy as np
import scipy.linalg
import scipy.sparse
import threadpoolctl

from tatl_mj.transfer import fit_time
from tatl_mj.transfer.features import Features, OneHot, as_states, make_features
from tatl_mj.transitions import Transitions
from tatl_mj.validation import choice, integer


@runtime_checkable
class QFunction(Protocol):
    """An action-value function over a discrete action set."""

    n_actions: int

    def values(self, states: np.ndarray) -> np.ndarray:
        """(N, d) states -> (N, n_actions) Q-values."""
        ...

    def greedy(self, states: np.ndarray) -> np.ndarray:
        """(N, d) states -> (N,) int64 index of the best action (lowest index on ties)."""
        ...


def _argmax(values: np.ndarray) -> np.ndarray:
    return np.argmax(values, axis=1).astype(np.int64)


# --- Regressors (configurations) ---------------------------------------------


@dataclasses.dataclass(frozen=True)
class LinearRegressor:
    """Linear-in-features Q: ``Q(s, a) = w_a . phi(s)``, fitted by ridge least squares.

    ``ridge`` is added to the diagonal of each action's Gram matrix ``Phi_a^T Phi_a``;
    with ``ridge = 0`` a rank-deficient basis raises ValueError instead of guessing.

    ``precision`` is that of FQI's two passes over the samples' features per
    iteration (the least squares are always solved in double). ``"single"`` halves
    their memory traffic, about twice as fast on large batches. It suits
    well-regularised fits: a fit moves by at most ``1 / (2 sqrt(ridge))`` times the
    rounding of its targets (~1e-7 relative), which the iteration accumulates over
    the ``1 / (1 - gamma)`` iterations its values look ahead. With a ridge near 0, a fit with fewer samples than
    features amplifies that rounding at the next states, which lie off the fitted
    samples, and a greedy policy can change.

    ``next_pass`` values the next states each iteration by ``"matrix"``, one product
    over every sample (BLAS's gemm, which copies all the features into its packed
    layout each call: the larger cost with few actions), or ``"blocked"``, a
    matrix-vector product per action on blocks of samples that stay in cache: the
    same sums in another order (equal up to rounding), about 2x as fast in single
    precision on 256 features, 1.4x in double on 100.
    """

    features: Features
    ridge: float = 1e-6
    precision: str = "double"
    next_pass: str = "matrix"

    def __post_init__(self) -> None:
        if not isinstance(self.features, Features):
            raise ValueError(f"LinearRegressor.features must be a basis (callable with size()), got {self.features!r}")
        if not (math.isfinite(self.ridge) and self.ridge >= 0):
            raise ValueError(f"LinearRegressor.ridge must be a finite number >= 0, got {self.ridge!r}")
        choice("LinearRegressor", "precision", self.precision, PRECISIONS)
        choice("LinearRegressor", "next_pass", self.next_pass, NEXT_PASSES)


@dataclasses.dataclass(frozen=True)
class ExtraTrees:
    """Extremely randomised trees on ``(s, a)`` (Ernst et al. 2005), via scikit-learn.

    ``seed`` fixes the trees' randomness; when None, :func:`fitted_q_iteration`
    draws one from its ``rng`` (or uses 0 without one), so runs are reproducible.
    """

    n_estimators: int = 50
    min_samples_split: int = 5
    min_samples_leaf: int = 2
    seed: int | None = None

    def __post_init__(self) -> None:
        for name, least in (("n_estimators", 1), ("min_samples_split", 2), ("min_samples_leaf", 1)):
            integer("ExtraTrees", name, getattr(self, name), least)


Regressor = LinearRegressor | ExtraTrees
REGRESSOR_KINDS = ("linear", "extra_trees")
PRECISIONS = ("double", "single")
NEXT_PASSES = ("matrix", "blocked")
_DTYPES = {"double": np.float64, "single": np.float32}


def make_regressor(spec: dict[str, Any], state_dim: int) -> Regressor:
    """Builds a regressor from a plain dict.

    - ``{"kind": "linear", "features": {<features spec>}, "ridge": 1e-6, "precision": "double",
      "next_pass": "matrix"}``
      (see :func:`tatl_mj.transfer.features.make_features`);
    - ``{"kind": "extra_trees", "n_estimators": 50, "min_samples_split": 5,
      "min_samples_leaf": 2, "seed": 0}``.

    A learner section may carry both ``features`` and ``seed`` whatever its kind, so
    ``seed`` is accepted and unused for "linear" (closed form, no randomness) and
    ``features`` is accepted and unused for "extra_trees" (trees split raw states).
    """
    if not isinstance(spec, dict):
        raise ValueError(f"regressor spec must be a dict, got {type(spec).__name__}")
    kind = spec.get("kind")
    valid = {
        "linear": {"kind", "features", "ridge", "precision", "next_pass", "seed"},
        "extra_trees": {"kind", "n_estimators", "min_samples_split", "min_samples_leaf", "seed", "features"},
    }
    if kind not in valid:
        raise ValueError(f"regressor kind {kind!r} is unknown; valid kinds: {list(REGRESSOR_KINDS)}")
    unknown = sorted(set(spec) - valid[kind])
    if unknown:
        raise ValueError(f"unknown keys {unknown} in {kind} regressor spec; valid keys: {sorted(valid[kind])}")
    if kind == "linear":
        if "features" not in spec:
            raise ValueError("linear regressor spec lacks 'features'")
        features = make_features(spec["features"], state_dim)
        return LinearRegressor(
            features, float(spec.get("ridge", 1e-6)), spec.get("precision", "double"), spec.get("next_pass", "matrix")
        )
    kwargs = {k: v for k, v in spec.items() if k not in ("kind", "features")}
    return ExtraTrees(**kwargs)


# --- Fitted Q-functions -------------------------------------------------------


@dataclasses.dataclass(frozen=True, eq=False)
class LinearQ:
    """``Q(s, a) = weights[a] . features(s)``; weights (n_actions, k)."""

    features: Features
    weights: np.ndarray

    @property
    def n_actions(self) -> int:
        return len(self.weights)

    def values(self, states: np.ndarray) -> np.ndarray:
        if isinstance(self.features, OneHot):
            # phi is an indicator: phi @ W^T picks a column exactly (the other terms are
            # exact zeros), without building phi; grid episodes ask one cell a call.
            return self.weights[:, self.features.index(states)].T
        return self.features(states) @ self.weights.T

    def greedy(self, states: np.ndarray) -> np.ndarray:
        return _argmax(self.values(states))


@dataclasses.dataclass(frozen=True, eq=False)
class TreeQ:
    """A scikit-learn forest over inputs ``[s, a]`` (a: the action index)."""

    forest: Any  # sklearn.ensemble.ExtraTreesRegressor (imported where a tree is fitted)
    n_actions: int
    state_dim: int

    def values(self, states: np.ndarray) -> np.ndarray:
        s = as_states(states, dim=self.state_dim)
        n = len(s)
        inputs = np.hstack([np.tile(s, (self.n_actions, 1)), np.repeat(np.arange(self.n_actions), n)[:, None]])
        return self.forest.predict(inputs).reshape(self.n_actions, n).T

    def greedy(self, states: np.ndarray) -> np.ndarray:
        return _argmax(self.values(states))


@dataclasses.dataclass(frozen=True, eq=False)
class ResidualQ:
    """``Q = prior + residual``: a fixed prior Q-function plus a fitted correction."""

    prior: QFunction
    residual: QFunction

    @property
    def n_actions(self) -> int:
        return self.residual.n_actions

    def values(self, states: np.ndarray) -> np.ndarray:
        return self.prior.values(states) + self.residual.values(states)

    def greedy(self, states: np.ndarray) -> np.ndarray:
        return _argmax(self.values(states))


@dataclasses.dataclass(frozen=True, eq=False)
class ZeroQ:
    """Q = 0 everywhere (FQI's Q_0 when no initial Q is given)."""

    n_actions: int

    def values(self, states: np.ndarray) -> np.ndarray:
        return np.zeros((len(states), self.n_actions))

    def greedy(self, states: np.ndarray) -> np.ndarray:
        return np.zeros(len(states), dtype=np.int64)


def greedy_each(q: QFunction, states: np.ndarray) -> np.ndarray:
    """(N,) each row's greedy action exactly as ``q.greedy(states[i:i + 1])`` gives it.

    A product over a batch may sum in another order than a one-row product (the
    last bits differ, and a near tie may then break the other way). A linear Q on
    a ``row_exact`` basis evaluates the basis once and the product row by row;
    any other Q is asked one state at a time.
    """
    s = np.asarray(states, np.float64)
    if isinstance(q, LinearQ) and isinstance(q.features, OneHot):
        return q.greedy(s)  # a column picked per row
    if isinstance(q, LinearQ) and getattr(q.features, "row_exact", False):
        phi, weights = q.features(s), q.weights.T
        return np.array([np.argmax(phi[i : i + 1] @ weights) for i in range(len(s))], np.int64)
    return np.array([q.greedy(s[i : i + 1])[0] for i in range(len(s))], np.int64)


# --- FQI ----------------------------------------------------------------------


def _check_fqi_inputs(
    transitions: Transitions, n_actions: int, gamma: float, iterations: int, initial_q: QFunction | None
) -> None:
    if not isinstance(transitions, Transitions):
        raise ValueError(f"transitions must be a Transitions, got {type(transitions).__name__}")
    if len(transitions) == 0:
        raise ValueError("transitions is empty; FQI needs at least one transition per action")
    integer("", "n_actions", n_actions, 1)
    if not (isinstance(gamma, (int, float)) and 0.0 <= gamma < 1.0):
        raise ValueError(f"gamma must be in [0, 1), got {gamma!r}")
    integer("", "iterations", iterations, 1)
    a = transitions.actions
    if a.min() < 0 or a.max() >= n_actions:
        raise ValueError(f"transitions.actions must be indices in 0..{n_actions - 1}, got range {a.min()}..{a.max()}")
    if initial_q is not None and initial_q.n_actions != n_actions:
        raise ValueError(f"initial_q has {initial_q.n_actions} actions, expected n_actions={n_actions}")


@fit_time.timed
def fitted_q_iteration(
    transitions: Transitions,
    n_actions: int,
    regressor: Regressor,
    gamma: float,
    iterations: int,
    initial_q: QFunction | None = None,
    rng: np.random.Generator | None = None,
    prior_q: QFunction | None = None,
) -> QFunction:
    """Fitted Q-Iteration; returns Q_K (K = ``iterations``) with a greedy policy.

    ``initial_q`` is Q_0, the bootstrap of the first iteration (UMA-TL); absorbing
    transitions bootstrap nothing, a time limit (``last`` without ``absorbing``) does.
    ``prior_q`` (not with ``initial_q``) makes every iterate ``prior_q + residual``,
    the regressor fitting ``y - prior_q(s, a)``; Q_0 is then ``prior_q`` itself.
    """
    _check_fqi_inputs(transitions, n_actions, gamma, iterations, initial_q)
    if prior_q is not None:
        if initial_q is not None:
            raise ValueError("give initial_q or prior_q, not both: with a prior, Q_0 is the prior")
        if prior_q.n_actions != n_actions:
            raise ValueError(f"prior_q has {prior_q.n_actions} actions, expected n_actions={n_actions}")
    q0 = initial_q if initial_q is not None else ZeroQ(int(n_actions))
    if isinstance(regressor, LinearRegressor):
        return _fqi_linear(transitions, int(n_actions), regressor, gamma, int(iterations), q0, prior_q)
    if isinstance(regressor, ExtraTrees):
        if regressor.seed is not None:
            seed = int(regressor.seed)
        else:
            seed = int(rng.integers(2**31 - 1)) if rng is not None else 0
        return _fqi_trees(transitions, int(n_actions), regressor, gamma, int(iterations), q0, seed, prior_q)
    raise ValueError(f"regressor must be a LinearRegressor or ExtraTrees, got {type(regressor).__name__}")


def _unique_rows(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct rows of x (N, d) and, per row, the index of its distinct row.

    np.unique(axis=0) sorts rows as opaque bytes, ~30x slower than a lexsort here.
    """
    order = np.lexsort(x.T[::-1])
    ordered = x[order]
    new = np.ones(len(x), dtype=bool)
    new[1:] = (ordered[1:] != ordered[:-1]).any(axis=1)
    inverse = np.empty(len(x), dtype=np.int64)
    inverse[order] = np.cumsum(new) - 1
    return ordered[new], inverse


def _fqi_linear(
    t: Transitions,
    n_actions: int,
    reg: LinearRegressor,
    gamma: float,
    iterations: int,
    q0: QFunction,
    prior: QFunction | None = None,
) -> LinearQ | ResidualQ:
    # Exact equal-state grouping: features and Q_0 are evaluated once per distinct state,
    # and when the distinct next states are few (a grid, a discretised task) each iteration
    # runs on the empirical model instead of the samples (_iterate_on_model).
    states, state_of = _unique_rows(t.states)
    nexts, next_of = _unique_rows(t.next_states)
    phi_states = reg.features(states)
    k = phi_states.shape[1]
    counts = np.zeros((n_actions, len(states)))
    np.add.at(counts, (t.actions, state_of), 1.0)
    factors = []
    for a in range(n_actions):
        seen = counts[a] > 0
        if not seen.any():
            raise ValueError(f"transitions contain no sample of action {a}; FQI cannot fit Q(., {a})")
        if reg.ridge == 0 and np.linalg.matrix_rank(phi_states[seen]) < k:
            raise ValueError(
                f"features are rank-deficient on the {int(counts[a].sum())} samples of action {a} "
                f"(basis size {k}); use ridge > 0, more samples or fewer features"
            )
        # Phi_a^T Phi_a summed over distinct states weighted by their counts; it never
        # changes between iterations, so it is factorised once.
        phi_seen = phi_states[seen]
        gram = (phi_seen.T * counts[a, seen]) @ phi_seen + reg.ridge * np.eye(k)
        factors.append(scipy.linalg.cho_factor(gram, check_finite=False))
    on_samples = prior is not None or len(nexts) * n_actions > len(t)
    if on_samples and isinstance(reg.features, OneHot):
        # Indicator columns add exact zeros to the one weight they pick: no features to store.
        phi_next: np.ndarray | _NextCells = _NextCells(reg.features.index(nexts))
    else:
        phi_next = reg.features(nexts)
    if prior is not None:
        # The residual's targets are y - prior(s, a); its bootstrap adds the prior back.
        prior_next = prior.values(nexts)
        prior_taken = prior.values(states)[state_of, t.actions]
        with threadpoolctl.threadpool_limits(limits=1, user_api="blas"):
            weights = _iterate_on_samples(
                t, n_actions, gamma, iterations, factors, phi_states, state_of, phi_next, next_of, prior_next,
                _DTYPES[reg.precision], prior_taken=prior_taken, prior_next=prior_next,
                blocked=reg.next_pass == "blocked",
            )  # fmt: skip
        return ResidualQ(prior, LinearQ(reg.features, weights))
    next_values = q0.values(nexts)
    # An iteration is a few memory-bound matrix-vector products: BLAS threads only add
    # synchronisation.
    blocked = reg.next_pass == "blocked"
    iterate = functools.partial(_iterate_on_samples, blocked=blocked) if on_samples else _iterate_on_model
    with threadpoolctl.threadpool_limits(limits=1, user_api="blas"):
        weights = iterate(
            t, n_actions, gamma, iterations, factors, phi_states, state_of, phi_next, next_of, next_values,
            _DTYPES[reg.precision],
        )  # fmt: skip
    return LinearQ(reg.features, weights)


def _iterate_on_samples(
    t,
    n_actions,
    gamma,
    iterations,
    factors,
    phi_states,
    state_of,
    phi_next,
    next_of,
    next_values,
    dtype,
    prior_taken=None,
    prior_next=None,
    blocked=False,
) -> np.ndarray:
    """FQI sample by sample: per iteration one pass over the next-state features (on a
    one-hot basis, a pick of weight columns: :class:`_NextCells`) and one over the state
    features (both stored action-block-contiguous, transposed, so each product is one
    BLAS call with a long inner dimension), in ``dtype``; ``blocked``: the next states'
    pass a block of samples at a time (``LinearRegressor.next_pass``). With
    ``prior_taken`` (N,) and ``prior_next`` (V, A) the weights fit the residual from that prior."""
    order = np.argsort(t.actions, kind="stable")
    bounds = np.searchsorted(t.actions[order], np.arange(n_actions + 1))
    blocks = [slice(int(bounds[a]), int(bounds[a + 1])) for a in range(n_actions)]
    phi_t = _gathered_columns(phi_states, state_of[order], dtype)  # (k, N)
    if isinstance(phi_next, _NextCells):
        cells = phi_next.index[next_of[order]]

        def next_pass(weights: np.ndarray) -> np.ndarray:
            return weights[:, cells]
    else:
        phi_next_t = _gathered_columns(phi_next, next_of[order], dtype)  # (k, N)
        next_pass = _blocked_pass(phi_next_t) if blocked else lambda weights: weights @ phi_next_t

    rewards = t.rewards[order]
    if prior_taken is not None:
        rewards = rewards - prior_taken[order]
    offset_t = 0.0 if prior_next is None else np.ascontiguousarray(prior_next[next_of[order]].T)  # (A, N)
    continues = gamma * (~t.absorbing[order])
    best_next = next_values[next_of[order]].max(axis=1)
    weights = np.zeros((n_actions, phi_t.shape[0]))
    solve = _cho_solver(factors)
    # In double, every astype below returns its input: the same operations as without them.
    for _ in range(iterations):
        y = (rewards + continues * best_next).astype(dtype, copy=False)
        for a, block in enumerate(blocks):
            weights[a] = solve(a, (phi_t[:, block] @ y[block]).astype(np.float64, copy=False))
        best_next = (next_pass(weights.astype(dtype, copy=False)) + offset_t).max(axis=0).astype(np.float64, copy=False)
    return weights


def _blocked_pass(phi_t: np.ndarray, cache_bytes: int = 1 << 19) -> Callable[[np.ndarray], np.ndarray]:
    """``weights @ phi_t`` (A, N) as one matrix-vector product per action on each block of
    columns, the block (``cache_bytes`` of features) read from memory once and from cache
    by the other actions' products."""
    k, n = phi_t.shape
    width = max(64, cache_bytes // (k * phi_t.itemsize))
    blocks = [slice(start, min(start + width, n)) for start in range(0, n, width)]

    def next_pass(weights: np.ndarray) -> np.ndarray:
        out = np.empty((len(weights), n), dtype=np.result_type(weights, phi_t))
        for block in blocks:
            features = phi_t[:, block]
            for a, row in enumerate(weights):
                np.matmul(row, features, out=out[a, block])
        return out

    return next_pass


@dataclasses.dataclass(frozen=True)
class _NextCells:
    """Next states on a one-hot basis, as each one's indicator index: a weight row's
    product with an indicator column is the weight it picks, bit for bit (the other
    terms are exact zeros), as ``LinearQ.values`` reads it."""

    index: np.ndarray


def _gathered_columns(matrix: np.ndarray, rows: np.ndarray, dtype: type = np.float64, block: int = 256) -> np.ndarray:
    """``np.ascontiguousarray(matrix[rows].T, dtype)``, gathered and transposed a block of
    rows at a time (a copy, so the same numbers): the block stays in cache, where the
    whole gather and then the whole transpose each go through memory (about 3x faster
    at 20,000 x 257)."""
    out = np.empty((matrix.shape[1], len(rows)), dtype=dtype)
    for start in range(0, len(rows), block):
        out[:, start : start + block] = matrix[rows[start : start + block]].T
    return out


def _cho_solver(factors: list[tuple[np.ndarray, bool]]) -> Callable[[int, np.ndarray], np.ndarray]:
    """``solve(a, b)``: what ``cho_solve(factors[a], b)`` returns, through LAPACK's potrs directly.

    cho_solve calls that same routine on the same factor, but its argument checks
    cost more than the solve at these sizes, and FQI solves A systems per iteration.
    """
    (potrs,) = scipy.linalg.get_lapack_funcs(("potrs",), (factors[0][0],))

    def solve(a: int, b: np.ndarray) -> np.ndarray:
        c, lower = factors[a]
        x, info = potrs(c, b, lower=lower)
        if info != 0:
            raise ValueError(f"illegal value in argument {-info} of LAPACK potrs")
        return x

    return solve


def _iterate_on_model(
    t, n_actions, gamma, iterations, factors, phi_states, state_of, phi_next, next_of, next_values, dtype
) -> np.ndarray:
    """FQI on the empirical model: with V distinct next states, Phi_a^T y_a =
    Phi_a^T r_a + gamma * S_a max_b Q(nexts, b), where S_a (k, V) sums the state features
    of action a's non-absorbing samples by next state; an iteration costs O(A k V), not O(N k).
    With one-hot features this is Q-iteration on the empirical (count) model."""
    n_states, n_next = len(phi_states), len(phi_next)
    k = phi_states.shape[1]
    reward_sums = np.zeros((n_actions, n_states))
    np.add.at(reward_sums, (t.actions, state_of), t.rewards)
    open_ = ~t.absorbing
    flows = scipy.sparse.coo_matrix(
        (np.ones(int(open_.sum())), (t.actions[open_] * n_states + state_of[open_], next_of[open_])),
        shape=(n_actions * n_states, n_next),
    ).tocsr()  # summed duplicates: transition counts (a, s) -> s'
    base = np.empty((n_actions, k))
    spread = np.empty((n_actions, k, n_next), dtype=dtype)
    for a in range(n_actions):
        base[a] = phi_states.T @ reward_sums[a]
        spread[a] = gamma * (flows[a * n_states : (a + 1) * n_states].T @ phi_states).T
    weights = np.zeros((n_actions, k))
    best_next = next_values.max(axis=1)
    solve = _cho_solver(factors)
    phi_next = phi_next.astype(dtype, copy=False)
    for _ in range(iterations):
        best = best_next.astype(dtype, copy=False)
        for a in range(n_actions):
            weights[a] = solve(a, base[a] + (spread[a] @ best).astype(np.float64, copy=False))
        best_next = (phi_next @ weights.T.astype(dtype, copy=False)).max(axis=1).astype(np.float64, copy=False)
    return weights


def _fqi_trees(
    t: Transitions,
    n_actions: int,
    reg: ExtraTrees,
    gamma: float,
    iterations: int,
    q0: QFunction,
    seed: int,
    prior: QFunction | None = None,
) -> TreeQ | ResidualQ:
    missing = sorted(set(range(n_actions)) - set(np.unique(t.actions).tolist()))
    if missing:
        raise ValueError(f"transitions contain no sample of actions {missing}; FQI cannot fit Q for them")
    if len(t) < reg.min_samples_split:
        raise ValueError(f"too few transitions ({len(t)}) for min_samples_split={reg.min_samples_split}")
    inputs = np.hstack([t.states, t.actions[:, None].astype(np.float64)])
    continues = gamma * (~t.absorbing)
    q: QFunction = q0 if prior is None else prior
    taken = 0.0 if prior is None else prior.values(t.states)[np.arange(len(t)), t.actions]
    from sklearn import ensemble  # scikit-learn takes seconds to import: only where trees are grown

    for _ in range(iterations):
        y = t.rewards + continues * q.values(t.next_states).max(axis=1) - taken

        forest = ensemble.ExtraTreesRegressor(
            n_estimators=reg.n_estimators,
            min_samples_split=reg.min_samples_split,
            min_samples_leaf=reg.min_samples_leaf,
            random_state=seed,
            n_jobs=1,
        )
        forest.fit(inputs, y)
        q = TreeQ(forest, n_actions, t.state_dim)
        if prior is not None:
            q = ResidualQ(prior, q)
    return q


__all__ = [
    "ExtraTrees",
    "LinearQ",
    "LinearRegressor",
    "NEXT_PASSES",
    "PRECISIONS",
    "QFunction",
    "REGRESSOR_KINDS",
    "Regressor",
    "ResidualQ",
    "TreeQ",
    "ZeroQ",
    "fitted_q_iteration",
    "greedy_each",
    "make_regressor",
]


def __getattr__(name: str) -> Any:
    # Source caches (source.pkl) pickled before tabular Q-iteration moved to tabular_q name
    # its class here; a resumed run still reads them.
    if name == "TabularQ":
        from tatl_mj.transfer.tabular_q import TabularQ

        return TabularQ
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
