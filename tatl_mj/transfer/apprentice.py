"""The target apprentice: a control-affine model of the target, learned by least squares.

Paper, eq. ``Apprentice_model``::

    P_hat^(T)(s, a):  s'  =  W_hat phi(s) + B_hat a  =  [W_hat  B_hat] [phi(s); a]

fitted to (s_i, a_i, s_{i+1}) triplets from a random policy (Algorithm 2, step
"solve the least square linear regression problem"), and grown batch by batch until
the projected source policy does no worse on the apprentice than on the true target
by more than zeta: ``U_M(pi) - U_Mhat(pi) <= zeta`` (Algorithm 2's stopping rule). As the paper
does, the runner may reuse the alignment samples for it.

Angles. A state coordinate marked ``periodic`` lives on the circle, wrapped to
``[-pi, pi)`` (the pendulum hangs at theta = +-pi, exactly at the wrap), so ``s'`` jumps
by 2 pi whenever a sample crosses it and no smooth W phi(s) + B a fits it. On such a
coordinate the same control-affine model is written in increments on the circle::

    s'_j  =  wrap(s_j + [W phi(s) + B a]_j),     fitted to the targets wrap(s'_j - s_j),

which is the paper's model for the (continuous) angle itself; the other coordinates
keep ``s' = W phi(s) + B a`` unchanged.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from typing import Any, Callable, Sequence

import numpy as np

from tatl_mj.description import CellMap, TaskDescription
from tatl_mj.transfer.features import (
    Features,
    LinearFeatures,
    OneHot,
    as_states,
    periodic_difference,
    periodic_mask,
    wrap_angle,
)
from tatl_mj.transitions import Transitions
from tatl_mj.validation import integer


def _as_actions(action_values: np.ndarray, n: int, name: str = "action_values") -> np.ndarray:
    a = np.asarray(action_values, dtype=np.float64)
    if a.ndim == 1:
        a = a[:, None]
    if a.ndim != 2 or len(a) != n:
        raise ValueError(f"{name} must be (N, m) with N={n}, got shape {np.shape(action_values)}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or infinite values")
    return a


@dataclasses.dataclass(frozen=True, eq=False)
class Apprentice:
    """``s' = W phi(s) + B a`` (paper eq. ``Apprentice_model``).

    Attributes:
      W: (d, k) weights of the basis phi (the drift F_hat(s) = W phi(s)).
      B: (d, m) control matrix B_hat.
      features: the basis phi, (N, d) -> (N, k).
      periodic: optional (d,) bools marking angle coordinates; on those, W phi(s) + B a
        is the increment on the circle and ``s' = wrap(s + W phi(s) + B a)``.

    :func:`fit_apprentice` builds one from data; given directly, W and B are float64
    arrays and ``periodic`` is None or the tuple :func:`periodic_mask` returns (it
    has an angle), checked here and kept as given.
    """

    W: np.ndarray
    B: np.ndarray
    features: Features
    periodic: tuple[bool, ...] | None = None

    def __post_init__(self) -> None:
        w, b = self.W, self.B
        for name, value in (("W", w), ("B", b)):
            if not (isinstance(value, np.ndarray) and value.dtype == np.float64 and value.ndim == 2):
                raise ValueError(f"Apprentice.{name} must be a 2-D float64 array, got {np.shape(value)} {type(value)}")
        if b.shape[0] != w.shape[0]:
            raise ValueError(f"Apprentice.W (d, k) and B (d, m) need the same d, got {w.shape} and {b.shape}")
        if not (np.all(np.isfinite(w)) and np.all(np.isfinite(b))):
            raise ValueError("Apprentice.W and B must be finite")
        mask = periodic_mask(self.periodic, w.shape[0], "Apprentice.periodic")
        if self.periodic is not None and (type(self.periodic) is not tuple or mask != self.periodic):
            raise ValueError(
                f"Apprentice.periodic must be None or a tuple of bools with an angle, got {self.periodic!r} "
                f"(periodic_mask gives it: {mask!r})"
            )

    @property
    def state_dim(self) -> int:
        return self.W.shape[0]

    @property
    def action_dim(self) -> int:
        return self.B.shape[1]

    def affine(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """``(A, B, c)`` with ``predict(s, a) = A s + B a + c`` exactly, or None.

        Exact for linear features without angles (``phi(s) = [1, s]`` or ``s``) and
        no periodic coordinate: then a horizon's responses have closed forms.
        """
        f = self.features
        if not isinstance(f, LinearFeatures) or f.periodic is not None or self.periodic is not None:
            return None
        d = self.state_dim
        if self.W.shape[1] != d + int(f.bias):
            return None
        c = self.W[:, 0].copy() if f.bias else np.zeros(d)
        return self.W[:, int(f.bias) :].copy(), self.B.copy(), c

    def drift(self, states: np.ndarray) -> np.ndarray:
        """F_hat(s) = W phi(s), (N, d), plus s on periodic coordinates (not wrapped).

        So ``predict(s, a)`` is ``drift(s) + B a``, wrapped on the periodic coordinates.
        """
        s = as_states(states, dim=self.state_dim)
        f = self.features(s) @ self.W.T
        if self.periodic is not None:
            cols = np.flatnonzero(self.periodic)
            f[:, cols] += s[:, cols]
        return f

    def predict(self, states: np.ndarray, action_values: np.ndarray) -> np.ndarray:
        """(N, d) states, (N, m) actions (actuator units) -> (N, d) predicted next states
        (periodic coordinates wrapped to [-pi, pi))."""
        s = as_states(states, dim=self.state_dim)
        a = _as_actions(action_values, len(s))
        if a.shape[1] != self.action_dim:
            raise ValueError(f"action_values must have {self.action_dim} columns, got {a.shape[1]}")
        return self.wrap(self.drift(s) + a @ self.B.T)

    def wrap(self, states: np.ndarray) -> np.ndarray:
        """(N, d) states with the periodic coordinates wrapped to [-pi, pi) (a copy)."""
        out = np.array(states, dtype=np.float64)
        if self.periodic is not None:
            cols = np.flatnonzero(self.periodic)
            out[..., cols] = wrap_angle(out[..., cols])
        return out

    def difference(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """``a - b`` between states, the shorter way round on periodic coordinates."""
        return periodic_difference(a, b, self.periodic)


def fit_apprentice(
    states: np.ndarray,
    action_values: np.ndarray,
    next_states: np.ndarray,
    features: Features,
    ridge: float = 0.0,
    periodic: Sequence[bool] | None = None,
) -> Apprentice:
    """Least-squares ``[W B] = argmin sum_i |s_{i+1} - [W B] psi(s_i, a_i)|^2``, psi = [phi(s); a].

    On ``periodic`` coordinates the target is the wrapped increment
    ``wrap(s_{i+1} - s_i)`` instead of ``s_{i+1}`` (see the module docstring). With
    ``ridge = 0`` the regressors psi must have full column rank (enough samples,
    the actions must vary, no basis function duplicating an action); otherwise a
    ValueError says which. ``ridge > 0`` solves the ridge problem instead.
    """
    s = as_states(states, "states")
    s_next = as_states(next_states, "next_states", s.shape[1])
    if len(s_next) != len(s):
        raise ValueError(f"next_states has {len(s_next)} rows, states has {len(s)}")
    a = _as_actions(action_values, len(s))
    if not (math.isfinite(ridge) and ridge >= 0):
        raise ValueError(f"ridge must be a finite number >= 0, got {ridge!r}")
    mask = periodic_mask(periodic, s.shape[1])
    if mask is not None:
        cols = np.flatnonzero(mask)
        s_next = s_next.copy()
        s_next[:, cols] = wrap_angle(s_next[:, cols] - s[:, cols])
    if ridge == 0:
        phi = features(s)
        psi = np.hstack([phi, a])
        n, p = psi.shape
        if n < p:
            raise ValueError(
                f"too few samples for the apprentice: {n} < {p} unknowns per state coordinate "
                f"({phi.shape[1]} features + {a.shape[1]} action entries)"
            )
        theta, _, rank, sv = np.linalg.lstsq(psi, s_next, rcond=None)
        if rank < p:
            hint = (
                "the actions do not vary"
                if np.linalg.matrix_rank(a - a.mean(axis=0)) < a.shape[1]
                else ("the features are linearly dependent on these states")
            )
            raise ValueError(
                f"apprentice regressors are rank-deficient (rank {rank} < {p}): {hint}; "
                "use ridge > 0 or more varied samples"
            )
    else:
        gram, moments = _counted_normal_equations(features, s, a, s_next) or _normal_equations(features, s, a, s_next)
        theta = np.linalg.solve(gram + ridge * np.eye(len(gram)), moments)
    k = len(theta) - a.shape[1]
    return Apprentice(W=theta[:k].T, B=theta[k:].T, features=features, periodic=mask)


def _normal_equations(
    features: Features, s: np.ndarray, a: np.ndarray, s_next: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``(psi^T psi, psi^T s_next)`` with psi = [phi(s), a]."""
    psi = np.hstack([features(s), a])
    return psi.T @ psi, psi.T @ s_next


def _counted_normal_equations(
    features: Features, s: np.ndarray, a: np.ndarray, s_next: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """``(psi^T psi, psi^T s_next)`` counted per cell, or None.

    With a one-hot basis and integer actions and targets (a grid's cells and
    moves) every entry is a sum of integers, which any order of summation gives
    exactly: these are the products' very bits, without forming psi (N, k + m).
    """
    if not isinstance(features, OneHot) or a.size == 0:
        return None
    for x in (a, s_next):
        # Integer-valued, and every partial sum below 2^53: exact in float64.
        if not np.array_equal(x, np.rint(x)) or len(x) * max(1.0, float(np.abs(x).max())) ** 2 >= 2.0**52:
            return None
    idx = features.index(s)
    k, m = features.size(s.shape[1]), a.shape[1]
    gram = np.zeros((k + m, k + m))
    gram[np.arange(k), np.arange(k)] = np.bincount(idx, minlength=k)
    for j in range(m):
        gram[:k, k + j] = gram[k + j, :k] = np.bincount(idx, weights=a[:, j], minlength=k)
    gram[k:, k:] = a.T @ a
    moments = np.empty((k + m, s_next.shape[1]))
    for j in range(s_next.shape[1]):
        moments[:k, j] = np.bincount(idx, weights=s_next[:, j], minlength=k)
    moments[k:] = a.T @ s_next
    return gram, moments


def learn_apprentice(
    transitions: Transitions,
    action_set: np.ndarray,
    features: Features,
    utility_gap: Callable[[Apprentice], float],
    zeta: float,
    batch: int,
    ridge: float = 0.0,
    periodic: Sequence[bool] | None = None,
    gaps: dict[int, float] | None = None,
    utility_gaps: Callable[[list[Apprentice]], Sequence[float]] | None = None,
) -> tuple[Apprentice, int]:
    """Algorithm 2: fit on the first n = batch, 2 batch, ... samples until the gap <= zeta.

    ``utility_gap(apprentice)`` returns U_M(pi) - U_Mhat(pi) for the projected source
    policy, or any other gap to compare one-sided with zeta (a relative one is
    non-negative); the runner computes it, as it needs the target simulator. Returns the
    apprentice and the number of target samples it used. Batches too small for a
    full-rank fit are skipped. If the rule is never met, the fit on all samples is
    returned with ``n_used = len(transitions)`` and a RuntimeWarning. ``periodic``
    marks angle coordinates, as in :func:`fit_apprentice`.

    ``utility_gaps(apprentices)``, if given, returns each one's ``utility_gap``
    in one call (one rollout of them side by side): the scan then fits the next
    sizes ahead of need, 1, 2, 4, ... at a time, and finds their gaps together.
    ``gaps`` maps head sizes n to the gaps already found for the first n of these
    very transitions with this ``utility_gap`` (at a smaller budget of the same
    stream); it is read and filled in. A head whose gap is known is not rolled
    out again, nor refitted if it missed zeta, unless it is the last. Either
    way the result is the same.
    """
    actions = _action_matrix(transitions, action_set, batch, zeta)
    total = len(transitions)
    periodic = periodic_mask(periodic, transitions.states.shape[1])  # bad masks fail here, not per batch
    sizes = list(range(batch, total, batch)) + [total]
    known = {} if gaps is None else gaps
    fit = _HeadFits(transitions, actions, features, ridge, periodic)
    last_error: ValueError | None = None
    apprentice: Apprentice | None = None
    ahead = 1  # how many sizes' gaps the next call of utility_gaps finds
    for i, n in enumerate(sizes):
        if known.get(n, -math.inf) > zeta and n < total:
            continue  # missed zeta before: refitting it would miss again
        result = fit(n)
        if isinstance(result, ValueError):
            last_error = result
            continue
        apprentice = result
        if n not in known:
            ahead = _find_gaps(sizes, i, apprentice, fit, known, utility_gap, utility_gaps, ahead)
        gap = known[n]
        if not math.isfinite(gap):
            raise ValueError(f"utility_gap returned {gap} for an apprentice fitted on {n} samples")
        if gap <= zeta:
            return apprentice, n
    if apprentice is None:
        raise ValueError(f"no apprentice could be fitted on all {total} samples: {last_error}")
    warnings.warn(
        f"apprentice stopping rule (Algorithm 2, gap <= {zeta}) not met with all {total} samples",
        RuntimeWarning,
        stacklevel=2,
    )
    return apprentice, total


def _action_matrix(transitions: Transitions, action_set: np.ndarray, batch: int, zeta: float) -> np.ndarray:
    """Algorithm 2's inputs checked; the action set as an (n_actions, m) matrix."""
    if not isinstance(transitions, Transitions):
        raise ValueError(f"transitions must be a Transitions, got {type(transitions).__name__}")
    actions = np.asarray(action_set, dtype=np.float64)
    actions = actions[:, None] if actions.ndim == 1 else actions
    if actions.ndim != 2 or not np.all(np.isfinite(actions)):
        raise ValueError(f"action_set must be a finite (n_actions, m) array, got shape {np.shape(action_set)}")
    if len(transitions) and (transitions.actions.min() < 0 or transitions.actions.max() >= len(actions)):
        raise ValueError(f"transitions.actions must index action_set (0..{len(actions) - 1})")
    integer("", "batch", batch, 1)
    if not (math.isfinite(zeta) and zeta >= 0):
        raise ValueError(f"zeta must be a finite number >= 0, got {zeta!r}")
    if len(transitions) == 0:
        raise ValueError("transitions is empty; the apprentice needs samples")
    return actions


@dataclasses.dataclass
class _HeadFits:
    """The apprentice on the first n transitions, for each n asked, fitted once; the
    ValueError instead where n samples are too few or too uniform for a full-rank fit."""

    transitions: Transitions
    actions: np.ndarray
    features: Features
    ridge: float
    periodic: tuple[bool, ...] | None
    fits: dict[int, Apprentice | ValueError] = dataclasses.field(default_factory=dict)

    def __call__(self, n: int) -> Apprentice | ValueError:
        if n not in self.fits:
            head = self.transitions.head(n)
            try:
                self.fits[n] = fit_apprentice(
                    head.states, self.actions[head.actions], head.next_states, self.features, self.ridge, self.periodic
                )
            except ValueError as error:  # too few or too uniform samples yet: grow the set
                self.fits[n] = error
        return self.fits[n]


def _find_gaps(
    sizes: list[int],
    i: int,
    apprentice: Apprentice,
    fit: _HeadFits,
    known: dict[int, float],
    utility_gap: Callable[[Apprentice], float],
    utility_gaps: Callable[[list[Apprentice]], Sequence[float]] | None,
    ahead: int,
) -> int:
    """Fills ``known`` with the gap of ``apprentice``, the fit on the first ``sizes[i]``
    samples, and, with ``utility_gaps``, those of up to ``ahead - 1`` next sizes, fitted
    now and rolled out together. Returns the next call's ``ahead``."""
    if utility_gaps is None:
        known[sizes[i]] = float(utility_gap(apprentice))
        return ahead
    # This size and the next ones, fitted now and rolled out together; the
    # chunk doubles, so a scan that stops early wastes at most its own work.
    chunk = [(sizes[i], apprentice)]
    for m in sizes[i + 1 :]:
        if len(chunk) == ahead:
            break
        fitted = fit(m) if m not in known else None
        if isinstance(fitted, Apprentice):
            chunk.append((m, fitted))
    for (m, _), gap in zip(chunk, utility_gaps([a for _, a in chunk])):
        known[m] = float(gap)
    return ahead * 2


def state_snap(target: TaskDescription) -> Callable[[np.ndarray], np.ndarray] | None:
    """How a model's predicted states are put back on the target's state set, or None.

    A task that takes indices lives on cells: predictions go to the nearest of its
    known model's cells, or without one are rounded into its state box. A
    continuous task's predictions stand as they are (None).
    """
    if not target.discrete:
        return None
    cells = CellMap(target.known_model()[3]) if target.known_model is not None else None

    def snap(states: np.ndarray) -> np.ndarray:
        if cells is None:
            return np.clip(np.rint(states), target.state_low, target.state_high)
        return cells.cells[cells.nearest(states)].astype(np.float64)

    return snap


def model_return(model: Any, policy: Callable[[np.ndarray], np.ndarray], **settings: Any) -> float:
    """U_Mhat(pi): ``policy``'s mean return when ``model`` stands in for the target
    (Algorithm 2); ``settings`` are :func:`model_returns`'s keywords."""
    return model_returns([model], policy, **settings)[0]


def model_returns(
    models: Sequence[Any],
    policy: Callable[[np.ndarray], np.ndarray],
    *,
    starts: np.ndarray,
    reward: Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
    action_values: np.ndarray,
    steps: int,
    snap: Callable[[np.ndarray], np.ndarray] | None = None,
) -> list[float]:
    """U_Mhat(pi) of each of ``models``: ``policy``'s mean return when it stands in
    for the target (Algorithm 2), their rollouts side by side.

    From each of ``starts`` (N, d), ``steps`` steps of the policy on
    ``model.predict(states, action_values)``, each scored by the target task's own
    ``reward(states, actions, next_states) -> (rewards, absorbing)``; an episode
    earns nothing after its absorbing step. ``policy`` returns action values (N, m)
    or indices into ``action_values`` (N,); ``snap`` (:func:`state_snap`) puts the
    predictions back on the target's states. NaN where the model diverges.

    The policy, the reward and ``snap`` are asked once a step for the states of
    every model still rolling out (each row on its own), so Algorithm 2's
    candidate apprentices cost about one rollout's calls together; each model
    steps its own states, and gets bit for bit what a rollout of it alone gives.
    """
    first = np.asarray(starts, dtype=np.float64)
    n_models, n_starts = len(models), len(first)
    states = np.repeat(first[None], n_models, axis=0)  # (models, starts, d)
    totals = np.zeros((n_models, n_starts))
    alive = np.ones((n_models, n_starts), dtype=bool)
    rolling = np.ones(n_models, dtype=bool)
    diverged = np.zeros(n_models, dtype=bool)
    with np.errstate(all="ignore"):
        for _ in range(steps):
            live = np.flatnonzero(rolling)
            now = states[live]
            flat = policy(now.reshape(-1, now.shape[2]))
            values = flat if flat.ndim == 2 else action_values[flat]
            action = flat.reshape(len(live), n_starts, *flat.shape[1:])
            next_states = _predict_each([models[i] for i in live], now, values.reshape(len(live), n_starts, -1))
            finite = np.isfinite(next_states).all(axis=(1, 2))
            diverged[live[~finite]] = True
            rolling[live[~finite]] = False
            live, now, action, next_states = live[finite], now[finite], action[finite], next_states[finite]
            if len(live) == 0:
                break
            flat_next = next_states.reshape(-1, next_states.shape[2])
            if snap is not None:
                flat_next = snap(flat_next)
            rewards, ended = reward(now.reshape(-1, now.shape[2]), action.reshape(-1, *action.shape[2:]), flat_next)
            totals[live] += np.where(alive[live], np.asarray(rewards).reshape(len(live), n_starts), 0.0)
            alive[live] &= ~np.asarray(ended).reshape(len(live), n_starts)
            states[live] = flat_next.reshape(len(live), n_starts, -1)
            rolling[live] = alive[live].any(axis=1)
            if not rolling.any():
                break
    return [float("nan") if diverged[i] else float(totals[i].mean()) for i in range(n_models)]


def _predict_each(models: list[Any], states: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Model i's ``predict(states[i], values[i])`` for each i, (M, N, d).

    Apprentices sharing one row-exact basis evaluate it once over every row and
    take their products as one stack (each product is the 2-D one ``predict``
    makes: the same bits); any other models predict one by one.
    """
    first = models[0]
    shared = getattr(getattr(first, "features", None), "row_exact", False) and all(
        isinstance(m, Apprentice) and m.features is first.features and m.periodic == first.periodic for m in models
    )
    if not shared:
        return np.stack([model.predict(states[i], values[i]) for i, model in enumerate(models)])
    n_models, n, d = states.shape
    phi = first.features(states.reshape(-1, d)).reshape(n_models, n, -1)
    actions = _as_actions(values.reshape(n_models * n, -1), n_models * n).reshape(n_models, n, -1)
    weights = np.stack([model.W for model in models])  # (M, d, k)
    controls = np.stack([model.B for model in models])  # (M, d, m)
    drift = np.matmul(phi, weights.transpose(0, 2, 1))
    cols = None if first.periodic is None else np.flatnonzero(first.periodic)
    if cols is not None:
        drift[..., cols] += states[..., cols]
    out = drift + np.matmul(actions, controls.transpose(0, 2, 1))
    if cols is not None:
        out[..., cols] = wrap_angle(out[..., cols])
    return out


__all__ = ["Apprentice", "fit_apprentice", "learn_apprentice", "model_return", "model_returns", "state_snap"]
