"""The theorem's premises, measured: how far a target is from what the paper's proof of TA-TL assumes.

The proof (paper, Section "Analysis") takes a control-affine target
``s' = F(s) + B a``, an apprentice ``s' = W phi(s) + B_hat a`` within delta of it,
``alpha = B / B_hat`` near 1, actions applied as requested, and an invertible
mapping; it concludes that the target follows the projected source trajectory,
``s' = s_hat_next + epsilon``. Each premise, and the conclusion, is measured here
by a pure function of arrays with a frozen result:

- delta: :func:`one_step_errors` (a continuous target), :func:`misprediction_rate` (a grid);
- alpha: :func:`finite_difference_B` of the target's step and :func:`alpha` = pinv(B_hat) B(s);
- control affinity: :func:`control_affinity` (the best ``c + b a`` fit of the next state over
  actions spanning the limits) and :func:`b_spread` (B(s) across states);
- feasibility: :func:`feasibility` (requested actions clipped or snapped);
- tracking, the conclusion: :func:`tracking` (the real next state against s_hat_next);
- the mapping's invertibility: :func:`round_trip`.

State errors are in units of the sample stream's standard deviation of ``s' - s``
per coordinate (:func:`step_scale`), the difference taken the shorter way round
on angles, so one threshold serves every coordinate and task.
:class:`PremiseThresholds` declares where each premise counts as failed
(docs/protocol.md, "The theorem's premises, measured", gives each one's reason);
:func:`failed` applies them. Nothing here steps a simulator: the target's step
enters as a function of the action (``tatl_mj.sampling.replay.control_step`` for
a MuJoCo task).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable, Sequence

import numpy as np

from tatl_mj.transfer.features import as_states, periodic_difference, periodic_mask
from tatl_mj.transfer.intertask_mapping import Mapping

Step = Callable[[np.ndarray], np.ndarray]
"""``step(action (m,)) -> (d,)``: the target's next state from one saved state, as a function of the action."""

FEASIBILITY_TOLERANCE = 0.1
"""A decision is infeasible when its applied action is more than this fraction of the
actuator's range away from the requested one (:func:`feasibility`)."""

AFFINITY_ACTIONS = 9
"""Actions, evenly spaced from the lower to the upper limit, of :func:`control_affinity`'s fit."""

_NO_EFFECT = 1e-9  # RMS spread (in step stds) below which the actions move a coordinate not at all


def _mask(periodic: Sequence[bool] | None, dim: int) -> tuple[bool, ...] | None:
    return periodic_mask(periodic, dim, "periodic")


def _scale(scale: Any, dim: int) -> np.ndarray:
    s = np.asarray(scale, dtype=np.float64).ravel()
    if s.shape != (dim,) or not np.all(np.isfinite(s) & (s > 0)):
        raise ValueError(
            f"scale must be {dim} finite numbers > 0 (the stream's step std per coordinate), got {scale!r}"
        )
    return s


def _rows(a: Any, name: str, dim: int | None = None) -> np.ndarray:
    """(N, d) float64; NaN allowed (a diverged prediction or step is measured, not refused)."""
    x = np.asarray(a, dtype=np.float64)
    if x.ndim != 2 or (dim is not None and x.shape[1] != dim):
        raise ValueError(f"{name} must be a 2-D array (N, {dim or 'd'}), got shape {x.shape}")
    return x


def _pair(a: Any, b: Any, names: tuple[str, str]) -> tuple[np.ndarray, np.ndarray]:
    x = _rows(a, names[0])
    y = _rows(b, names[1], x.shape[1])
    if len(x) != len(y) or len(x) == 0:
        raise ValueError(f"{names[0]} and {names[1]} must have the same number of rows (>= 1), got {len(x)}, {len(y)}")
    return x, y


def step_scale(states: np.ndarray, next_states: np.ndarray, periodic: Sequence[bool] | None = None) -> np.ndarray:
    """(d,) the standard deviation of ``s' - s`` over a sample stream, per coordinate
    (wrapped on ``periodic`` ones): the unit every state error here is measured in.
    Raises ValueError where a coordinate never moves (there is nothing to measure it by)."""
    s, s_next = _pair(states, next_states, ("states", "next_states"))
    std = periodic_difference(s_next, s, _mask(periodic, s.shape[1])).std(axis=0)
    still = np.flatnonzero(~(np.isfinite(std) & (std > 0)))
    if len(still):
        raise ValueError(f"the stream's s' - s has no spread on coordinates {still.tolist()}: nothing to scale by")
    return std


@dataclasses.dataclass(frozen=True)
class NormalisedErrors:
    """Errors between two sets of states, in step stds (``error / scale``, wrapped on angles).

    Attributes:
      per_coordinate: (d,) RMS over the samples of each coordinate's error.
      rms: the RMS over samples and coordinates: the summary the thresholds judge.
      worst: the largest over samples of one sample's RMS over coordinates (a sup, as
        the theorem's delta is).
      n: samples.
    """

    per_coordinate: np.ndarray
    rms: float
    worst: float
    n: int


def normalised_errors(
    a: np.ndarray, b: np.ndarray, scale: np.ndarray, periodic: Sequence[bool] | None
) -> NormalisedErrors:
    """``a - b`` per row, wrapped on ``periodic`` coordinates and divided by ``scale``, summarised."""
    x, y = _pair(a, b, ("a", "b"))
    e = periodic_difference(x, y, _mask(periodic, x.shape[1])) / _scale(scale, x.shape[1])
    with np.errstate(invalid="ignore", over="ignore"):
        squares = e**2
        per_sample = np.sqrt(squares.mean(axis=1))
        return NormalisedErrors(
            per_coordinate=np.sqrt(squares.mean(axis=0)),
            rms=float(np.sqrt(squares.mean())),
            worst=float(per_sample.max()),
            n=len(e),
        )


def one_step_errors(
    apprentice: Any,
    states: np.ndarray,
    actions: np.ndarray,
    next_states: np.ndarray,
    scale: np.ndarray,
    periodic: Sequence[bool] | None,
) -> NormalisedErrors:
    """delta: the apprentice's one-step prediction ``P_hat(s, a)`` against the real ``s'``.

    ``actions`` are action values (N, m) in actuator units (those applied); on the
    states the policy visits in evaluation this is the theorem's delta where it
    matters, on the sample stream's own states its fit.
    """
    s, s_next = _pair(states, next_states, ("states", "next_states"))
    return normalised_errors(apprentice.predict(s, actions), s_next, scale, periodic)


def misprediction_rate(
    apprentice: Any,
    states: np.ndarray,
    actions: np.ndarray,
    next_states: np.ndarray,
    snap: Callable[[np.ndarray], np.ndarray] | None,
) -> float:
    """delta on a grid: the fraction of steps whose predicted next cell is not the real one.

    ``snap`` puts predictions back on the task's cells (``apprentice.state_snap``);
    ``actions`` are the action values the apprentice was fitted with.
    """
    s, s_next = _pair(states, next_states, ("states", "next_states"))
    predicted = apprentice.predict(s, actions)
    if snap is not None:
        predicted = snap(predicted)
    return mispredicted(predicted, s_next)


def mispredicted(predicted: np.ndarray, next_states: np.ndarray) -> float:
    """The fraction of rows whose ``predicted`` next cell is not the real one (a NaN: a miss)."""
    p, s_next = _pair(predicted, next_states, ("predicted", "next_states"))
    return float(np.mean(~np.all(np.abs(p - s_next) <= 1e-9, axis=1)))


def finite_difference_B(
    step: Step,
    action: np.ndarray,
    eps: float = 1e-3,
    periodic: Sequence[bool] | None = None,
    low: np.ndarray | None = None,
    high: np.ndarray | None = None,
) -> np.ndarray:
    """(d, m) B(s) = d s'/d a by central differences of ``step`` at ``action`` (actuator units).

    Differences of periodic coordinates are wrapped. With ``low``/``high`` the point
    is moved inside ``[low + eps, high - eps]`` first, so that neither side crosses
    the actuator's clip (a clipped action has no slope to measure there).
    """
    a = np.asarray(action, dtype=np.float64).ravel()
    if not (math.isfinite(eps) and eps > 0):
        raise ValueError(f"eps must be a finite number > 0, got {eps!r}")
    if low is not None or high is not None:
        lo = np.broadcast_to(np.asarray(-np.inf if low is None else low, np.float64), a.shape) + eps
        hi = np.broadcast_to(np.asarray(np.inf if high is None else high, np.float64), a.shape) - eps
        if np.any(lo > hi):
            raise ValueError(f"the actuator range [{low}, {high}] is narrower than 2 eps = {2 * eps}")
        a = np.clip(a, lo, hi)
    columns = []
    for j in range(len(a)):
        e = np.zeros_like(a)
        e[j] = eps
        plus, minus = np.asarray(step(a + e), np.float64), np.asarray(step(a - e), np.float64)
        columns.append(periodic_difference(plus, minus, _mask(periodic, len(plus))) / (2.0 * eps))
    return np.stack(columns, axis=1)


@dataclasses.dataclass(frozen=True)
class Alpha:
    """alpha = pinv(B_hat) B(s) at each of N states.

    Attributes:
      value: (N, m, m); with one action each is the paper's scalar B / B_hat.
      error: (N,) ``||alpha - I||_2`` (``|alpha - 1|`` with one action).
    """

    value: np.ndarray
    error: np.ndarray

    @property
    def mean_error(self) -> float:
        return float(np.mean(self.error))

    @property
    def max_error(self) -> float:
        return float(np.max(self.error))


def alpha(B_hat: np.ndarray, B: np.ndarray) -> Alpha:
    """pinv(B_hat) B for the apprentice's (d, m) ``B_hat`` and the target's B(s), (d, m) or (N, d, m).

    K = pinv(B_hat) is the policy's gain, so alpha is what an action asked of the
    apprentice does in the target: 1 where the proof's cancellation is exact.
    """
    b_hat = np.atleast_2d(np.asarray(B_hat, dtype=np.float64))
    bs = np.asarray(B, dtype=np.float64)
    bs = bs[None] if bs.ndim == 2 else bs
    if bs.ndim != 3 or bs.shape[1:] != b_hat.shape:
        raise ValueError(f"B must be {b_hat.shape} or (N, {b_hat.shape[0]}, {b_hat.shape[1]}), got {np.shape(B)}")
    value = np.linalg.pinv(b_hat)[None] @ bs
    eye = np.eye(b_hat.shape[1])
    return Alpha(value=value, error=np.linalg.norm(value - eye, ord=2, axis=(1, 2)))


def b_spread(Bs: np.ndarray, scale: np.ndarray | None = None) -> float:
    """The spread of B(s) across states: ``sqrt(mean_i ||B_i - mean B||_F^2) / ||mean B||_F``.

    0 for a constant B (the proof's); each row is divided by ``scale`` first (so
    every coordinate counts in step stds per unit of action). inf where the mean is 0.
    """
    bs = np.asarray(Bs, dtype=np.float64)
    if bs.ndim != 3 or len(bs) == 0:
        raise ValueError(f"Bs must be (N, d, m) with N >= 1, got shape {bs.shape}")
    if scale is not None:
        bs = bs / _scale(scale, bs.shape[1])[None, :, None]
    mean = bs.mean(axis=0)
    size = np.linalg.norm(mean)
    spread = math.sqrt(float(np.mean(np.sum((bs - mean) ** 2, axis=(1, 2)))))
    return math.inf if size == 0 else spread / size


@dataclasses.dataclass(frozen=True)
class Affinity:
    """How affine one state's next state is in the action.

    Attributes:
      unexplained: the pooled unexplained fraction ``sum(residual^2) / sum(centred^2)``
        over actions and coordinates (in step stds where scaled) of the least-squares
        fit ``s' ~ c + b a``: 0 for a control-affine step, 1 where a line explains nothing.
        0 where the actions move nothing.
      per_coordinate: (d,) the same per coordinate (NaN where the actions move it not at all).
      b: (d, m) the fit's slope, the secant B over the actions' span (unscaled).
    """

    unexplained: float
    per_coordinate: np.ndarray
    b: np.ndarray


def spanning_actions(low: np.ndarray, high: np.ndarray, n: int = AFFINITY_ACTIONS) -> np.ndarray:
    """(k, m) actions spanning the limits: n evenly spaced from limit to limit for one
    actuator; for several, n along each with the others at mid-range, the mid-range point once."""
    lo, hi = np.atleast_1d(np.asarray(low, np.float64)), np.atleast_1d(np.asarray(high, np.float64))
    if lo.shape != hi.shape or lo.ndim != 1 or not np.all(np.isfinite(lo) & np.isfinite(hi) & (lo < hi)):
        raise ValueError(f"low and high must be finite (m,) limits with low < high, got {low!r}, {high!r}")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 3:
        raise ValueError(f"n must be an integer >= 3 (a line through 2 points explains them), got {n!r}")
    mid, m = (lo + hi) / 2.0, len(lo)
    rows = [mid] if m > 1 else []
    for j in range(m):
        for value in np.linspace(lo[j], hi[j], n):
            if m > 1 and value == mid[j]:
                continue
            row = mid.copy()
            row[j] = value
            rows.append(row)
    return np.array(rows)


def affine_fit(
    actions: np.ndarray,
    next_states: np.ndarray,
    scale: np.ndarray | None = None,
    periodic: Sequence[bool] | None = None,
) -> Affinity:
    """:class:`Affinity` of next states (k, d) reached from one state by actions (k, m)."""
    a = np.asarray(actions, dtype=np.float64)
    a = a[:, None] if a.ndim == 1 else a
    y = _rows(next_states, "next_states")
    if a.ndim != 2 or len(a) != len(y) or len(a) < a.shape[1] + 2:
        raise ValueError(f"actions (k, m) and next_states (k, d) need k >= m + 2 rows, got {a.shape}, {y.shape}")
    if not np.all(np.isfinite(y)):  # a step MuJoCo refused: nothing to fit
        return Affinity(
            unexplained=math.nan, per_coordinate=np.full(y.shape[1], np.nan), b=np.full(a.shape[::-1], np.nan)
        )
    # Increments from the first action's next state: an angle's values then lie on one branch.
    y = periodic_difference(y, y[:1], _mask(periodic, y.shape[1]))
    if scale is not None:
        y = y / _scale(scale, y.shape[1])
    design = np.hstack([np.ones((len(a), 1)), a])
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    residual = ((y - design @ coef) ** 2).sum(axis=0)
    total = ((y - y.mean(axis=0)) ** 2).sum(axis=0)
    moved = total > len(y) * _NO_EFFECT**2
    per = np.full(y.shape[1], np.nan)
    per[moved] = residual[moved] / total[moved]
    pooled = float(residual[moved].sum() / total[moved].sum()) if moved.any() else 0.0
    b = coef[1:].T * (1.0 if scale is None else np.asarray(scale, np.float64).ravel()[:, None])
    return Affinity(unexplained=pooled, per_coordinate=per, b=b)


def control_affinity(
    step: Step,
    low: np.ndarray,
    high: np.ndarray,
    n: int = AFFINITY_ACTIONS,
    scale: np.ndarray | None = None,
    periodic: Sequence[bool] | None = None,
) -> Affinity:
    """:func:`affine_fit` of ``step``'s next states over :func:`spanning_actions` ``(low, high, n)``."""
    actions = spanning_actions(low, high, n)
    return affine_fit(actions, np.stack([np.asarray(step(a), np.float64) for a in actions]), scale, periodic)


@dataclasses.dataclass(frozen=True)
class Feasibility:
    """Whether the actions Algorithm 1 asked for were the ones applied.

    Attributes:
      clipped: fraction of decisions whose request lay outside the actuator's limits.
      snapped: fraction whose applied action differs from the request clipped to the
        limits (moved to an admissible action).
      infeasible: fraction whose applied action is more than ``tolerance`` of the
        actuator's range from the request: the one the thresholds judge.
      mean_excess, max_excess: ``max_j |applied_j - requested_j| / (high_j - low_j)``
        averaged over and largest among the decisions.
      tolerance: the fraction of the range ``infeasible`` allows.
      n: decisions.
    """

    clipped: float
    snapped: float
    infeasible: float
    mean_excess: float
    max_excess: float
    tolerance: float
    n: int


def feasibility(
    requested: np.ndarray,
    applied: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    tolerance: float = FEASIBILITY_TOLERANCE,
) -> Feasibility:
    """:class:`Feasibility` of decisions: ``requested`` = mapped action + K pi_ad (before
    any clip, ``TATLStep.a_T + TATLStep.adaptive``), ``applied`` the action taken, both (N, m)."""
    req, app = _pair(requested, applied, ("requested", "applied"))
    lo = np.broadcast_to(np.asarray(low, np.float64), (req.shape[1],))
    hi = np.broadcast_to(np.asarray(high, np.float64), (req.shape[1],))
    span = hi - lo
    if not np.all(np.isfinite(span) & (span > 0)):
        raise ValueError(f"low and high must be finite limits with low < high, got {low!r}, {high!r}")
    if not (math.isfinite(tolerance) and tolerance >= 0):
        raise ValueError(f"tolerance must be a finite number >= 0, got {tolerance!r}")
    rounding = 1e-12 * span  # what a clip or a snap leaves of an exact request
    clipped = np.any((req < lo - rounding) | (req > hi + rounding), axis=1)
    snapped = np.any(np.abs(app - np.clip(req, lo, hi)) > rounding, axis=1)
    excess = np.max(np.abs(app - req) / span, axis=1)
    return Feasibility(
        clipped=float(clipped.mean()),
        snapped=float(snapped.mean()),
        infeasible=float(np.mean(~(excess <= tolerance))),  # NaN: not shown feasible
        mean_excess=float(excess.mean()),
        max_excess=float(excess.max()),
        tolerance=float(tolerance),
        n=len(req),
    )


def tracking(
    next_states: np.ndarray,
    projected_next_states: np.ndarray,
    scale: np.ndarray,
    periodic: Sequence[bool] | None,
) -> NormalisedErrors:
    """The theorem's conclusion: the real next state against the projected source next
    state ``s_hat_next = chi(P_S(chi_plus(s), a_S))`` of the same decision."""
    return normalised_errors(next_states, projected_next_states, scale, periodic)


def round_trip(
    mapping: Mapping, states: np.ndarray, scale: np.ndarray, periodic: Sequence[bool] | None
) -> NormalisedErrors:
    """The mapping's invertibility on target ``states``: ``chi(chi_plus(s)) - s`` in target
    coordinates; 0 for an invertible map, what the lost directions hold for a projection."""
    s = as_states(states, "states")  # the states themselves must be real ones
    return normalised_errors(mapping.chi(mapping.chi_plus(s)), s, scale, periodic)


@dataclasses.dataclass(frozen=True)
class PremiseMeasurements:
    """One method's premise measurements on one seed; None where not measured for it.

    Attributes:
      delta: :func:`one_step_errors` ``.rms`` on the states the policy visits in evaluation.
      delta_stream: the same on the sample stream's own states: reported, not judged.
      misprediction: :func:`misprediction_rate` on the visited states (a grid's delta).
      alpha: :attr:`Alpha.mean_error` over the finite-difference states.
      unexplained: mean :attr:`Affinity.unexplained` over the finite-difference states.
      b_spread: :func:`b_spread` of B(s) over the finite-difference states.
      infeasible: :attr:`Feasibility.infeasible` over the evaluation's decisions.
      tracking: :func:`tracking` ``.rms`` over the evaluation's decisions.
      round_trip: :func:`round_trip` ``.rms`` on the visited states.
    """

    delta: float | None = None
    delta_stream: float | None = None
    misprediction: float | None = None
    alpha: float | None = None
    unexplained: float | None = None
    b_spread: float | None = None
    infeasible: float | None = None
    tracking: float | None = None
    round_trip: float | None = None


@dataclasses.dataclass(frozen=True)
class PremiseThresholds:
    """Where each premise counts as failed: a measurement above its threshold (or NaN).

    Declared before any tuning run, from the theory (docs/protocol.md, "The
    theorem's premises, measured", gives each one's reason). State errors are in
    step stds, alpha and the spread relative, the rest fractions.
    """

    delta: float = 0.5
    misprediction: float = 0.25
    alpha: float = 0.5
    unexplained: float = 0.1
    b_spread: float = 0.25
    infeasible: float = 0.5
    tracking: float = 1.0
    round_trip: float = 0.5

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not (0 < value < math.inf):
                raise ValueError(f"PremiseThresholds.{field.name} must be a finite number > 0, got {value!r}")


THRESHOLDS = PremiseThresholds()
"""The declared thresholds."""


def failed(measurements: PremiseMeasurements, thresholds: PremiseThresholds = THRESHOLDS) -> tuple[str, ...]:
    """The names of the measured premises above their thresholds, in the thresholds' order.

    A premise not measured (None) is not judged; a NaN one (a diverged prediction)
    fails, as nothing shows it holds.
    """
    if not isinstance(measurements, PremiseMeasurements):
        raise ValueError(f"measurements must be PremiseMeasurements, got {type(measurements).__name__}")
    out = []
    for field in dataclasses.fields(thresholds):
        value = getattr(measurements, field.name)
        if value is not None and not value <= getattr(thresholds, field.name):
            out.append(field.name)
    return tuple(out)


__all__ = [
    "AFFINITY_ACTIONS",
    "Affinity",
    "Alpha",
    "FEASIBILITY_TOLERANCE",
    "Feasibility",
    "NormalisedErrors",
    "PremiseMeasurements",
    "PremiseThresholds",
    "Step",
    "THRESHOLDS",
    "affine_fit",
    "alpha",
    "b_spread",
    "control_affinity",
    "failed",
    "feasibility",
    "finite_difference_B",
    "misprediction_rate",
    "mispredicted",
    "normalised_errors",
    "one_step_errors",
    "round_trip",
    "spanning_actions",
    "step_scale",
]
