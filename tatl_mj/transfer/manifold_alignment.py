"""The paper's inter-task mapping (Phase II): Unsupervised Manifold Alignment.

The paper maps states between tasks with Unsupervised Manifold Alignment (UMA;
Wang & Mahadevan 2009, "Manifold alignment without correspondence", as used for RL
transfer by Ammar et al. 2015). :func:`align_manifolds` implements it in three steps:

1. **Standardise** each data set (centre it and, by default, whiten it), so that a
   linear map between the tasks becomes a rotation between the standardised clouds
   and distances in both are in comparable units.
2. **Correspondences from local geometry** (W&M 2009, Sec. 3.1): each point's
   neighbourhood (the point and its k nearest neighbours) is summarised by its
   permutation-invariant pairwise-distance profile (the sorted distances of its
   (k+1)(k+2)/2 pairs, in units of the set's median neighbour distance). A
   source point and a target point whose profiles are close get a correspondence
   weight ``W_ij = exp(-|R_i - R_j|^2 / 2 delta^2)`` (kept for each point's few best
   partners, both ways). Sorting the distances replaces W&M's search over the k!
   neighbour orders.
3. **Joint-Laplacian alignment** (W&M 2009, Sec. 3.2, the linear "feature-level"
   case): with Z = blockdiag(X^T, Y^T), the joint graph
   ``[[W_x, mu W], [mu W^T, W_y]]`` (W_x, W_y: k-nearest-neighbour heat-kernel graphs of
   each set), D its degree and L = D - W, the projections gamma = [alpha; beta] solve
   the generalised eigenproblem ``Z L Z^T gamma = lambda Z D Z^T gamma`` (smallest
   ``dim`` eigenvalues; ``scipy.linalg.eigh``). Then alpha^T x and beta^T y are the
   shared coordinates and, as in Ammar et al. (2015),
   ``chi = (beta^T)^+ alpha^T`` and ``chi_plus = (alpha^T)^+ beta^T`` (pseudo-inverses,
   least squares where the dimensions differ), wrapped in the standardisations.

The result, a :class:`LinearAlignment`, satisfies the
:class:`~tatl_mj.transfer.intertask_mapping.Mapping` protocol.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import scipy.linalg
import scipy.sparse
from scipy.spatial import distance

from tatl_mj.transfer.features import as_states
from tatl_mj.validation import integer


@dataclasses.dataclass(frozen=True, eq=False)
class LinearAlignment:
    """A mapping through a shared space: the result of :func:`align_manifolds`.

    Standardised coordinates are ``z = (s - mean) @ whitener.T``; shared coordinates
    are ``z_S @ alpha`` and ``z_T @ beta``.

    Attributes:
      source_mean, source_whitener: (dS,), (dS, dS).
      target_mean, target_whitener: (dT,), (dT, dT).
      alpha: (dS, dim) source projection; beta: (dT, dim) target projection.
      eigenvalues: (dim,) alignment cost of each shared coordinate (smaller is better).
    """

    source_mean: np.ndarray
    source_whitener: np.ndarray
    target_mean: np.ndarray
    target_whitener: np.ndarray
    alpha: np.ndarray
    beta: np.ndarray
    eigenvalues: np.ndarray

    # chi = (beta^T)^+ alpha^T in standardised coordinates, likewise chi_plus; each derived once.
    @functools.cached_property
    def _chi_z(self) -> np.ndarray:
        return np.linalg.pinv(self.beta.T) @ self.alpha.T

    @functools.cached_property
    def _chi_plus_z(self) -> np.ndarray:
        return np.linalg.pinv(self.alpha.T) @ self.beta.T

    @functools.cached_property
    def _source_unwhiten(self) -> np.ndarray:
        return np.linalg.inv(self.source_whitener)

    @functools.cached_property
    def _target_unwhiten(self) -> np.ndarray:
        return np.linalg.inv(self.target_whitener)

    def embed_source(self, source_states: np.ndarray) -> np.ndarray:
        """(N, dS) -> (N, dim) shared coordinates."""
        s = as_states(source_states, "source_states", len(self.source_mean))
        return (s - self.source_mean) @ self.source_whitener.T @ self.alpha

    def embed_target(self, target_states: np.ndarray) -> np.ndarray:
        """(N, dT) -> (N, dim) shared coordinates."""
        s = as_states(target_states, "target_states", len(self.target_mean))
        return (s - self.target_mean) @ self.target_whitener.T @ self.beta

    def chi(self, source_states: np.ndarray) -> np.ndarray:
        s = as_states(source_states, "source_states", len(self.source_mean))
        z = (s - self.source_mean) @ self.source_whitener.T
        return (z @ self._chi_z.T) @ self._target_unwhiten.T + self.target_mean

    def chi_plus(self, target_states: np.ndarray) -> np.ndarray:
        s = as_states(target_states, "target_states", len(self.target_mean))
        z = (s - self.target_mean) @ self.target_whitener.T
        return (z @ self._chi_plus_z.T) @ self._source_unwhiten.T + self.source_mean


def standardiser(x: np.ndarray, name: str, whiten: bool) -> tuple[np.ndarray, np.ndarray]:
    """Mean and matrix T with ``(x - mean) @ T.T`` centred and whitened (or unit-variance)."""
    mean = x.mean(axis=0)
    centred = x - mean
    if whiten:
        cov = centred.T @ centred / len(x)
        eigval, eigvec = np.linalg.eigh(cov)
        if eigval.min() <= 1e-12 * max(eigval.max(), 1e-300):
            raise ValueError(
                f"{name} are rank-deficient (a constant or linearly dependent coordinate); drop it before aligning"
            )
        return mean, (eigvec / np.sqrt(eigval)) @ eigvec.T
    std = centred.std(axis=0)
    if np.any(std <= 1e-12 * max(std.max(), 1e-300)):
        raise ValueError(f"{name} coordinate(s) {np.flatnonzero(std <= 1e-12 * std.max()).tolist()} are constant")
    return mean, np.diag(1.0 / std)


def _knn_graph(z: np.ndarray, k: int) -> scipy.sparse.csr_matrix:
    """Symmetric k-nearest-neighbour graph with heat-kernel weights (bandwidth: median distance)."""
    from sklearn import neighbors  # scikit-learn takes seconds to import: only where a graph is built

    graph = neighbors.kneighbors_graph(z, k, mode="distance", include_self=False)
    scale = np.median(graph.data)
    graph.data = np.exp(-((graph.data / scale) ** 2) / 2.0)
    return graph.maximum(graph.T).tocsr()


def local_geometry(z: np.ndarray, k: int) -> np.ndarray:
    """(N, k(k+1)/2 + k) permutation-invariant descriptors of each point's k-neighbourhood.

    The sorted pairwise distances among a point and its k nearest neighbours
    (W&M 2009's local distance matrix R_i, made independent of the neighbours'
    order), in units of the set's median nearest-neighbour distance.
    """
    from sklearn import neighbors

    _, idx = neighbors.NearestNeighbors(n_neighbors=k + 1).fit(z).kneighbors(z)
    patches = z[idx]  # (N, k+1, d), the point itself first
    diff = patches[:, :, None, :] - patches[:, None, :, :]
    dist = np.sqrt(np.einsum("nijd,nijd->nij", diff, diff))
    upper = np.triu_indices(k + 1, 1)
    profile = np.sort(dist[:, upper[0], upper[1]], axis=1)
    return profile / np.median(dist[:, 0, 1])


def correspondences(
    source_z: np.ndarray, target_z: np.ndarray, n_neighbors: int, n_matches: int
) -> scipy.sparse.csr_matrix:
    """(nS, nT) correspondence weights W from local geometry (W&M 2009, Sec. 3.1).

    Each point keeps its ``n_matches`` most similar partners in the other set
    (the union of both directions), weighted by a heat kernel on descriptor distance.
    """
    rs = local_geometry(source_z, n_neighbors)
    rt = local_geometry(target_z, n_neighbors)
    d = distance.cdist(rs, rt)
    n_s, n_t = d.shape
    rows = np.repeat(np.arange(n_s), n_matches)
    cols = np.argpartition(d, n_matches - 1, axis=1)[:, :n_matches].ravel()
    rows_t = np.argpartition(d, n_matches - 1, axis=0)[:n_matches, :].T.ravel()
    cols_t = np.repeat(np.arange(n_t), n_matches)
    delta = max(np.median(np.concatenate([d[rows, cols], d[rows_t, cols_t]])), 1e-12)

    def heat(r: np.ndarray, c: np.ndarray) -> scipy.sparse.csr_matrix:
        weights = np.exp(-((d[r, c] / delta) ** 2) / 2.0)
        return scipy.sparse.csr_matrix((weights, (r, c)), shape=d.shape)

    # A pair chosen from both sides keeps one weight, not two.
    w = heat(rows, cols).maximum(heat(rows_t, cols_t))
    return w


def align_manifolds(
    source_states: np.ndarray,
    target_states: np.ndarray,
    n_neighbors: int = 8,
    dim: int | None = None,
    mu: float = 1.0,
    rng: np.random.Generator | None = None,
    whiten: bool = True,
    n_matches: int = 3,
    max_samples: int = 1500,
) -> LinearAlignment:
    """Unsupervised manifold alignment of two sample sets (see the module docstring).

    Args:
      source_states: (nS, dS) samples of the source (e.g. from a random policy).
      target_states: (nT, dT) samples of the target.
      n_neighbors: k of the neighbourhood graphs and of the local-geometry patches.
      dim: shared-space dimension, default ``min(dS, dT)``; with ``dim = dS = dT``
        chi and chi_plus are exact inverses of each other.
      mu: weight of the correspondence term against the two graphs' smoothness.
      rng: draws the subsample when a set has more than ``max_samples`` points
        (the correspondence step is quadratic in the set sizes); default seed 0.
      whiten: whiten each set (covariance I) rather than only scale each coordinate.
      n_matches: partners kept per point in the correspondence matrix.
    """
    xs = as_states(source_states, "source_states")
    xt = as_states(target_states, "target_states")
    integer("", "n_neighbors", n_neighbors, 2)
    integer("", "n_matches", n_matches, 1)
    if not (np.isfinite(mu) and mu > 0):
        raise ValueError(f"mu must be a finite number > 0, got {mu!r}")
    d_s, d_t = xs.shape[1], xt.shape[1]
    dim = min(d_s, d_t) if dim is None else dim
    integer("", "dim", dim, 1, min(d_s, d_t), unit=" (min of the state dims)")
    least = max(n_neighbors + 2, n_matches + 1, d_s + d_t + 1)
    for name, x in (("source_states", xs), ("target_states", xt)):
        if len(x) < least:
            raise ValueError(f"{name} has {len(x)} samples; alignment needs at least {least}")
    rng = rng if rng is not None else np.random.default_rng(0)
    if len(xs) > max_samples:
        xs = xs[rng.choice(len(xs), max_samples, replace=False)]
    if len(xt) > max_samples:
        xt = xt[rng.choice(len(xt), max_samples, replace=False)]

    mean_s, white_s = standardiser(xs, "source_states", whiten)
    mean_t, white_t = standardiser(xt, "target_states", whiten)
    zs = (xs - mean_s) @ white_s.T
    zt = (xt - mean_t) @ white_t.T

    w = correspondences(zs, zt, n_neighbors, n_matches)
    joint = scipy.sparse.bmat([[_knn_graph(zs, n_neighbors), mu * w], [mu * w.T, _knn_graph(zt, n_neighbors)]]).tocsr()
    degree = np.asarray(joint.sum(axis=1)).ravel()
    laplacian = scipy.sparse.diags(degree) - joint
    z = scipy.linalg.block_diag(zs, zt)  # (nS + nT, dS + dT) = Z^T
    lhs = z.T @ (laplacian @ z)
    rhs = z.T @ (degree[:, None] * z)
    lhs = (lhs + lhs.T) / 2.0
    try:
        eigenvalues, gamma = scipy.linalg.eigh(lhs, rhs, subset_by_index=[0, dim - 1])
    except np.linalg.LinAlgError as error:
        raise ValueError(f"manifold alignment eigenproblem is degenerate ({error}); check the samples") from error
    return LinearAlignment(
        source_mean=mean_s,
        source_whitener=white_s,
        target_mean=mean_t,
        target_whitener=white_t,
        alpha=gamma[:d_s],
        beta=gamma[d_s:],
        eigenvalues=eigenvalues,
    )


__all__ = [
    "LinearAlignment",
    "align_manifolds",
    "correspondences",
    "local_geometry",
    "standardiser",
]
