"""Basis functions phi(s) for linear Q-functions (FQI) and the target apprentice.

The paper approximates Q (Phase I) and the target model (eq. ``Apprentice_model``,
``s' = W phi(s) + B a``) with a single layer of fixed bases. Three are provided:

- :class:`RBF`: Gaussian radial basis functions with given centres and a diagonal
  or full bandwidth (the paper's 20 centres, sigma = 1.2 I for the pendulum and
  diag(0.3, 0.1) for mountain car), plus an optional constant;
- :class:`LinearFeatures`: ``[1, s]`` (the paper's plain linear basis for cart-pole);
- :class:`OneHot`: a tabular indicator of a grid-world cell ``[row, col]``.

Angles: :class:`RBF` and :class:`LinearFeatures` take an optional ``periodic`` mask (one
bool per state coordinate). A periodic coordinate is an angle on the circle, wrapped to
``[-pi, pi)`` (the pendulum's theta, hanging down at the wrap): the RBF measures the
wrapped difference ``wrap(s - c)`` so it is 2 pi-periodic there, and the linear basis
uses ``[sin, cos]`` of the angle instead of the raw value. :func:`wrap_angle` and
:func:`periodic_mask` are shared with the apprentice and the TA-TL policy.

Every basis is a frozen dataclass with ``__call__(states (N, d)) -> (N, k)`` float64
and ``size(state_dim) -> k``. :func:`make_features` builds one from a plain dict.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import math
from typing import Any, Protocol, Sequence, runtime_checkable

import numpy as np

from tatl_mj.validation import Constraint, InvalidSetting, integer

TWO_PI = 2.0 * np.pi


def wrap_angle(x: np.ndarray) -> np.ndarray:
    """Angles wrapped to ``[-pi, pi)``: ``(x + pi) mod 2 pi - pi``."""
    return np.mod(np.asarray(x, dtype=np.float64) + np.pi, TWO_PI) - np.pi


def periodic_mask(periodic: Any, dim: int | None = None, name: str = "periodic") -> tuple[bool, ...] | None:
    """Checks a per-coordinate periodic mask: None, or ``dim`` bools (a tuple is returned).

    A mask with no True entry is returned as None, so "no angles" has one spelling.
    """
    if periodic is None:
        return None
    if isinstance(periodic, (str, bytes)) or np.ndim(periodic) != 1:
        raise ValueError(f"{name} must be a sequence of bools, one per state coordinate, got {periodic!r}")
    values = list(periodic)
    if not all(isinstance(v, (bool, np.bool_)) for v in values):
        raise ValueError(f"{name} entries must be bools (true/false), got {values!r}")
    if dim is not None and len(values) != dim:
        raise ValueError(f"{name} must have one entry per state coordinate ({dim}), got {len(values)}")
    mask = tuple(bool(v) for v in values)
    return mask if any(mask) else None


def periodic_difference(a: np.ndarray, b: np.ndarray, periodic: tuple[bool, ...] | None) -> np.ndarray:
    """``a - b``, wrapped to ``[-pi, pi)`` on the periodic coordinates (last axis)."""
    diff = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    if periodic is not None:
        cols = np.flatnonzero(periodic)
        diff[..., cols] = wrap_angle(diff[..., cols])
    return diff


@runtime_checkable
class Features(Protocol):
    """A fixed basis phi: (N, d) states -> (N, k) float64.

    A basis may set ``row_exact = True``: a call on N states gives each row bit
    for bit what a call on that state alone gives (no product that sums across
    coordinates runs with the batch as one of its dimensions, where BLAS may sum
    in another order). A policy stepped one state a call can then be answered for
    many episodes at once with the same actions (:func:`tatl_mj.transfer.fqi.greedy_each`).
    """

    def __call__(self, states: np.ndarray) -> np.ndarray: ...

    def size(self, state_dim: int) -> int: ...


def as_states(states: Any, name: str = "states", dim: int | None = None) -> np.ndarray:
    """Checks a batch of states: 2-D float64, finite, ``dim`` columns when given."""
    s = np.asarray(states, dtype=np.float64)
    if s.ndim != 2:
        raise ValueError(f"{name} must be a 2-D array (N, d), got shape {s.shape}")
    if dim is not None and s.shape[1] != dim:
        raise ValueError(f"{name} must have {dim} columns, got shape {s.shape}")
    if not np.isfinite(s).all():  # the method, not np.all: one state a call in episode loops
        raise ValueError(f"{name} contains NaN or infinite values")
    return s


@dataclasses.dataclass(frozen=True, eq=False)
class RBF:
    """Gaussian radial basis functions ``phi_j(s) = exp(-|L^-1 (s - c_j)|^2 / 2)``.

    Attributes:
      centers: (k, d) centres c_j.
      sigma: the bandwidth L: (d,) per-coordinate widths (L = diag(sigma), in
        state units) or a (d, d) matrix (e.g. 1.2 I); it must be invertible.
      bias: prepend a constant 1 (so ``size = k + 1``).
      periodic: optional (d,) bools; on a True coordinate ``s - c_j`` is replaced by
        the wrapped difference ``(s - c_j + pi) mod 2 pi - pi``, so phi is 2 pi-periodic
        in that angle and +pi, -pi are one point.
    """

    centers: np.ndarray
    sigma: np.ndarray
    bias: bool = True
    periodic: tuple[bool, ...] | None = None

    def __post_init__(self) -> None:
        centers = np.atleast_2d(np.asarray(self.centers, dtype=np.float64))
        if centers.ndim != 2 or centers.shape[0] == 0:
            raise ValueError(f"RBF.centers must be a non-empty (k, d) array, got shape {centers.shape}")
        if not np.all(np.isfinite(centers)):
            raise ValueError("RBF.centers contains NaN or infinite values")
        d = centers.shape[1]
        sigma = np.asarray(self.sigma, dtype=np.float64)
        if sigma.ndim == 0:
            sigma = np.full(d, float(sigma))
        if sigma.shape == (d,):
            if not np.all(np.isfinite(sigma)) or np.any(sigma <= 0):
                raise ValueError(f"RBF.sigma must be finite and > 0, got {sigma}")
            sigma = np.diag(sigma)
        elif sigma.shape != (d, d):
            raise ValueError(f"RBF.sigma must have shape ({d},) or ({d}, {d}), got {sigma.shape}")
        if not np.all(np.isfinite(sigma)) or np.linalg.cond(sigma) > 1e12:
            raise ValueError(f"RBF.sigma must be a finite invertible matrix, got {sigma.tolist()}")
        object.__setattr__(self, "centers", centers)
        object.__setattr__(self, "sigma", sigma)
        object.__setattr__(self, "periodic", periodic_mask(self.periodic, d, "RBF.periodic"))

    # Centres and states are whitened by L once, so a call is one distance matrix.
    @functools.cached_property
    def _inverse(self) -> np.ndarray:
        return np.linalg.inv(self.sigma)

    @functools.cached_property
    def _scaled_centers(self) -> np.ndarray:
        return self.centers @ self._inverse.T

    @staticmethod
    def grid(
        low: Sequence[float],
        high: Sequence[float],
        n_centers: int | Sequence[int],
        sigma: Any,
        bias: bool = True,
        periodic: Sequence[bool] | None = None,
    ) -> "RBF":
        """Centres on a regular grid spanning the box ``[low, high]`` (ends included).

        On a ``periodic`` coordinate the centres are spaced over ``[low, high)``
        instead (high is excluded: with ``[-pi, pi)`` a centre at -pi is also one at
        +pi); such a coordinate may span at most 2 pi.

        ``n_centers`` is either the count per dimension (a sequence) or a total
        (an int), which is split into per-dimension counts whose product is
        exactly that total, as even as possible, with more centres along the
        dimensions that are wider relative to ``sigma`` (20 in 2-D gives 5 x 4).
        A dimension with one centre puts it in the middle of the box.
        """
        lo = np.asarray(low, dtype=np.float64).ravel()
        hi = np.asarray(high, dtype=np.float64).ravel()
        if lo.shape != hi.shape or lo.size == 0:
            raise ValueError(f"RBF.grid low and high must be equal-length vectors, got {lo.shape} and {hi.shape}")
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi > lo)):
            raise ValueError(f"RBF.grid needs finite low < high, got low={lo.tolist()} high={hi.tolist()}")
        d = lo.size
        mask = periodic_mask(periodic, d, "RBF.grid periodic") or (False,) * d
        too_wide = [j for j in range(d) if mask[j] and hi[j] - lo[j] > TWO_PI * (1 + 1e-9)]
        if too_wide:
            raise ValueError(
                f"RBF.grid periodic coordinates {too_wide} span more than 2 pi "
                f"(low={lo.tolist()}, high={hi.tolist()}); an angle's centres lie within one turn"
            )
        if isinstance(n_centers, (int, np.integer)):
            # The basis's width along each coordinate: |row j of L| (|sigma_j| for a diagonal L).
            # L is validated first, as the basis below would (a ValueError naming sigma), so a
            # width is never 0 and the spans never divide by zero.
            widths = np.linalg.norm(RBF(np.zeros((1, d)), sigma).sigma, axis=1)
            counts = _split_count(int(n_centers), (hi - lo) / widths)
        else:
            counts = [int(c) for c in n_centers]
            if len(counts) != d or min(counts) < 1:
                raise ValueError(f"RBF.grid n_centers must be {d} positive counts, got {list(n_centers)}")
        axes = [
            np.linspace(l, h, c, endpoint=not p) if c > 1 else np.array([(l + h) / 2])
            for l, h, c, p in zip(lo, hi, counts, mask)
        ]
        centers = np.array(list(itertools.product(*axes)), dtype=np.float64)
        return RBF(centers, sigma, bias, periodic)

    def size(self, state_dim: int) -> int:
        return len(self.centers) + int(self.bias)

    @property
    def row_exact(self) -> bool:
        """Periodic distances are formed state by state; plain ones are one product over the batch."""
        return self.periodic is not None

    @functools.cached_property
    def _diagonal(self) -> np.ndarray | None:
        """L^-1's diagonal where L is diagonal and d <= 2, else None (see
        :meth:`_wrapped_sq_distances_diagonal`). Derived on first use, so a basis
        pickled without it (an older run's source) gets it too."""
        inverse = self._inverse
        # Beyond 2 coordinates einsum sums in SIMD lanes, in an order a plain sum does not reproduce.
        if inverse.shape[0] > 2 or np.count_nonzero(inverse - np.diag(np.diag(inverse))):
            return None
        return np.diag(inverse).copy()

    @functools.cached_property
    def _grid_values(self) -> list[np.ndarray] | None:
        """Each coordinate's distinct centre values when the centres are their product in
        row-major order (the layout of :meth:`grid`), else None."""
        axes = [np.unique(column, return_inverse=True) for column in self.centers.T]
        counts = [len(values) for values, _ in axes]
        if math.prod(counts) != len(self.centers):
            return None
        layout = np.indices(counts).reshape(len(counts), -1)
        if not all(np.array_equal(index, layout[j]) for j, (_, index) in enumerate(axes)):
            return None
        return [values for values, _ in axes]

    @functools.cached_property
    def _center_norms(self) -> np.ndarray:
        """|L^-1 c_j|^2 (k,): the same every call."""
        return np.einsum("ij,ij->i", self._scaled_centers, self._scaled_centers)

    def __call__(self, states: np.ndarray) -> np.ndarray:
        raw = as_states(states, dim=self.centers.shape[1])
        out = np.empty((len(raw), len(self.centers) + int(self.bias)))
        sq = out[:, 1:] if self.bias else out  # filled in place: no copy behind the constant
        if self.periodic is None:
            s = raw @ self._inverse.T
            # |s|^2 - 2 s.c + |c|^2, each step in place (no (N, k) temporaries): the same operations.
            np.matmul(2.0 * s, self._scaled_centers.T, out=sq)
            np.subtract(np.einsum("ij,ij->i", s, s)[:, None], sq, out=sq)
            np.add(sq, self._center_norms, out=sq)
            np.maximum(sq, 0.0, out=sq)  # rounding may leave a tiny negative
        else:
            self._wrapped_sq_distances(raw, sq)  # a sum of squares
        sq *= -0.5
        np.exp(sq, out=sq)
        if self.bias:
            out[:, 0] = 1.0
        return out

    def _wrapped_sq_distances(self, s: np.ndarray, out: np.ndarray) -> None:
        """out (N, k) = |L^-1 wrap(s - c_j)|^2. The wrap is not a dot product, so the
        differences are formed explicitly, in row blocks to bound memory."""
        if self._diagonal is not None:
            self._wrapped_sq_distances_diagonal(s, out)
            return
        k, d = self.centers.shape
        rows = max(1, (1 << 21) // (k * d))
        for start in range(0, len(s), rows):
            diff = periodic_difference(s[start : start + rows, None, :], self.centers[None, :, :], self.periodic)
            z = diff @ self._inverse.T
            out[start : start + rows] = np.einsum("nkd,nkd->nk", z, z)

    def _wrapped_sq_distances_diagonal(self, s: np.ndarray, out: np.ndarray) -> None:
        """:meth:`_wrapped_sq_distances` for a diagonal L, bit for bit: the same
        differences, wraps and products (the matrix form's other terms are exact
        zeros), summed in the same order, one coordinate at a time.

        On a grid of centres a coordinate's term depends on the state and that
        coordinate's value alone, so it is formed once per distinct value (10 of
        the pendulum's 100 centres) and the two terms are added by broadcasting."""
        grid = self._grid_values
        if grid is not None:
            terms = [self._coordinate_term(s, j, values) for j, values in enumerate(grid)]
            if len(terms) == 1:
                out[...] = terms[0]
                return
            cube = out.reshape(len(s), *(len(v) for v in grid))
            if np.shares_memory(cube, out):  # a view: numpy splits a contiguous axis without copying
                np.add(terms[0][:, :, None], terms[1][:, None, :], out=cube)
                return
        rows = max(1, (1 << 21) // len(self.centers))  # one (rows, k) term beside the output
        for start in range(0, len(s), rows):
            block, part = s[start : start + rows], out[start : start + rows]
            part[...] = self._coordinate_term(block, 0, self.centers[:, 0])
            for j in range(1, len(self._diagonal)):
                part += self._coordinate_term(block, j, self.centers[:, j])

    def _coordinate_term(self, s: np.ndarray, j: int, values: np.ndarray) -> np.ndarray:
        """(N, len(values)): ``(scale_j * wrap(s_j - value))^2``, wrapped on a periodic coordinate."""
        term = np.subtract(s[:, j : j + 1], values[None, :])
        if self.periodic[j]:  # wrap_angle, in place
            term += np.pi
            np.mod(term, TWO_PI, out=term)
            term -= np.pi
        term *= self._diagonal[j]
        term *= term
        return term


def _split_count(total: int, spans: np.ndarray) -> list[int]:
    """Per-dimension counts with product ``total``: as even as possible, more on wide spans."""
    if total < 1:
        raise ValueError(f"RBF.grid n_centers must be >= 1, got {total}")
    d = len(spans)

    def factorisations(n: int, parts: int) -> list[tuple[int, ...]]:
        if parts == 1:
            return [(n,)]
        out = []
        for f in range(1, n + 1):
            if n % f == 0:
                out.extend((f,) + rest for rest in factorisations(n // f, parts - 1))
        return out

    if total > 10_000:
        raise ValueError(f"RBF.grid n_centers={total} is too many; give per-dimension counts")
    # Evenness first, then wide-span dimensions get the larger counts.
    best = min(factorisations(total, d), key=lambda f: (max(f) - min(f), sorted(f)))
    order = np.argsort(-spans, kind="stable")
    counts = [0] * d
    for dim, count in zip(order, sorted(best, reverse=True)):
        counts[int(dim)] = count
    return counts


@dataclasses.dataclass(frozen=True)
class LinearFeatures:
    """``phi(s) = [1, s]`` (or ``s`` when ``bias`` is False).

    With a ``periodic`` mask each periodic coordinate s_j is replaced, in place, by
    the pair ``[sin s_j, cos s_j]`` (continuous across the wrap, unlike s_j itself),
    so ``size = d + (number of periodic coordinates) + bias``.
    """

    bias: bool = True
    periodic: tuple[bool, ...] | None = None
    row_exact = True  # elementwise

    def __post_init__(self) -> None:
        object.__setattr__(self, "periodic", periodic_mask(self.periodic, None, "LinearFeatures.periodic"))

    def _check_dim(self, state_dim: int) -> None:
        if self.periodic is not None and len(self.periodic) != state_dim:
            raise ValueError(
                f"LinearFeatures.periodic has {len(self.periodic)} entries, the states have {state_dim} coordinates"
            )

    def size(self, state_dim: int) -> int:
        self._check_dim(state_dim)
        return state_dim + (sum(self.periodic) if self.periodic else 0) + int(self.bias)

    def __call__(self, states: np.ndarray) -> np.ndarray:
        s = as_states(states)
        self._check_dim(s.shape[1])
        if self.periodic is not None:
            columns = [
                np.stack([np.sin(s[:, j]), np.cos(s[:, j])], axis=1) if p else s[:, j : j + 1]
                for j, p in enumerate(self.periodic)
            ]
            s = np.hstack(columns)
        return np.hstack([np.ones((len(s), 1)), s]) if self.bias else s.copy()


@dataclasses.dataclass(frozen=True)
class OneHot:
    """Tabular indicator of a grid cell: state ``[row, col]`` -> e_{row * n_cols + col}.

    Rows and columns must be integers (within 1e-9) inside the grid; anything
    else raises ValueError, since a tabular basis cannot generalise.
    """

    n_rows: int
    n_cols: int
    row_exact = True  # an indicator per row

    def __post_init__(self) -> None:
        for name in ("n_rows", "n_cols"):
            integer("OneHot", name, getattr(self, name), 1)

    def size(self, state_dim: int) -> int:
        return self.n_rows * self.n_cols

    def index(self, states: np.ndarray) -> np.ndarray:
        """(N, 2) cells [row, col] -> (N,) int64 indices ``row * n_cols + col``."""
        s = as_states(states, dim=2)
        cells = np.rint(s)
        if (np.abs(s - cells) > 1e-9).any():
            raise ValueError("OneHot states must be integer [row, col] cells")
        rows, cols = cells[:, 0].astype(np.int64), cells[:, 1].astype(np.int64)
        if ((rows < 0) | (rows >= self.n_rows) | (cols < 0) | (cols >= self.n_cols)).any():
            raise ValueError(f"OneHot states must lie in the {self.n_rows} x {self.n_cols} grid")
        return rows * self.n_cols + cols

    def __call__(self, states: np.ndarray) -> np.ndarray:
        idx = self.index(states)
        phi = np.zeros((len(idx), self.n_rows * self.n_cols))
        phi[np.arange(len(idx)), idx] = 1.0
        return phi


FEATURE_KINDS = ("rbf", "linear", "onehot")
_FEATURE_KEYS = {
    "rbf": {"kind", "centers", "low", "high", "sigma", "bias", "periodic"},
    "linear": {"kind", "bias", "periodic"},
    "onehot": {"kind", "n_rows", "n_cols"},
}


def make_features(spec: dict[str, Any], state_dim: int) -> Features:
    """Builds a basis from a plain dict (e.g. a TOML table).

    - ``{"kind": "rbf", "centers": 20, "low": [...], "high": [...], "sigma": [1.2, 1.2]}``:
      ``centers`` is a total count, per-dimension counts, or an explicit (k, d)
      list of centres (then ``low``/``high`` are not needed); ``bias`` defaults to True.
    - ``{"kind": "linear", "bias": True}``
    - ``{"kind": "onehot", "n_rows": 6, "n_cols": 9}``

    ``rbf`` and ``linear`` accept ``"periodic": [true, false]`` (one bool per state
    coordinate) to treat angles as points on the circle (see :class:`RBF`,
    :class:`LinearFeatures`, :meth:`RBF.grid`).

    Unknown kinds or keys, and values of the wrong type, raise ValueError.
    """
    try:
        return _make_features(spec, state_dim)
    except TypeError as error:
        raise ValueError(f"features spec {spec!r} has a value of the wrong type: {error}") from None


def _make_features(spec: dict[str, Any], state_dim: int) -> Features:
    if not isinstance(spec, dict):
        raise ValueError(f"features spec must be a dict, got {type(spec).__name__}")
    kind = spec.get("kind")
    if kind not in FEATURE_KINDS:
        raise ValueError(f"features kind {kind!r} is unknown; valid kinds: {list(FEATURE_KINDS)}")
    unknown = sorted(set(spec) - _FEATURE_KEYS[kind])
    if unknown:
        raise ValueError(f"unknown keys {unknown} in {kind} features spec; valid keys: {sorted(_FEATURE_KEYS[kind])}")
    periodic = periodic_mask(spec.get("periodic"), state_dim, f"{kind} features periodic")
    if kind == "linear":
        return LinearFeatures(bias=bool(spec.get("bias", True)), periodic=periodic)
    if kind == "onehot":
        missing = sorted({"n_rows", "n_cols"} - set(spec))
        if missing:
            raise ValueError(f"onehot features spec lacks {missing}")
        if state_dim != 2:
            raise ValueError(f"onehot features need [row, col] states (state_dim 2), got state_dim {state_dim}")
        return OneHot(int(spec["n_rows"]), int(spec["n_cols"]))
    for key in ("centers", "sigma"):
        if key not in spec:
            raise ValueError(f"rbf features spec lacks {key!r}")
    bias = bool(spec.get("bias", True))
    centers = spec["centers"]
    if isinstance(centers, (int, np.integer)) or np.ndim(centers) == 1:
        missing = sorted({"low", "high"} - set(spec))
        if missing:
            raise ValueError(f"rbf features spec with a centre count needs {missing}")
        if len(spec["low"]) != state_dim or len(spec["high"]) != state_dim:
            raise ValueError(f"rbf features low/high must have state_dim={state_dim} entries")
        return RBF.grid(spec["low"], spec["high"], centers, spec["sigma"], bias, periodic)
    rbf = RBF(np.asarray(centers, dtype=np.float64), spec["sigma"], bias, periodic)
    if rbf.centers.shape[1] != state_dim:
        raise ValueError(f"rbf features centers have {rbf.centers.shape[1]} columns, state_dim is {state_dim}")
    return rbf


class FeaturesSpec(Constraint):
    """A settings constraint: a features spec :func:`make_features` accepts (its keys and kinds;
    the sizes that need the task's state are checked by :func:`check_features`)."""

    def convert(self, value: Any) -> Any:
        make_features(value, _probe_dim(value))  # ValueError: why not
        return value

    def invalid(self) -> Any:
        return {"kind": "no-such-kind"}

    def __str__(self) -> str:
        return "a features table (make_features)"


def _probe_dim(spec: Any) -> int:
    """A state size that a basis spec can be built with, to check its keys before the task is known."""
    if isinstance(spec, dict):
        for key in ("low", "periodic"):
            if isinstance(spec.get(key), (list, tuple)):
                return len(spec[key])
        if spec.get("kind") == "onehot":
            return 2
    return 1


def check_features(owner: str, field: str, spec: Any, state_dim: int) -> None:
    """A basis spec builds for a task of ``state_dim`` coordinates (its sizes fit), else one line."""
    try:
        make_features(spec, state_dim)
    except ValueError as error:
        raise InvalidSetting(f"{owner}.{field}: {error}") from None


class Periodic(Constraint):
    """A settings constraint: a per-coordinate periodic mask (:func:`periodic_mask`), as a tuple
    of bools, or None where no entry is True."""

    def convert(self, value: Any) -> Any:
        return periodic_mask(value)

    def invalid(self) -> Any:
        return ("yes",)

    def __str__(self) -> str:
        return "a list of true/false, one per state coordinate"


__all__ = [
    "FEATURE_KINDS",
    "Features",
    "FeaturesSpec",
    "LinearFeatures",
    "OneHot",
    "Periodic",
    "RBF",
    "as_states",
    "check_features",
    "make_features",
    "periodic_difference",
    "periodic_mask",
    "wrap_angle",
]
