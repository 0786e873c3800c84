"""A transition-aware inter-task mapping (Phase II, ``mapping.kind = "transition_alignment"``).

:func:`align_transitions` is an optional, transition-aware variant of the paper's
manifold alignment, this project's own method, not Ammar et al.'s: Ammar et al. (2015)
align (s, a, s') triplets in one embedding; here candidate state maps (the sign
and permutation ambiguities that state samples alone leave open) are scored by
how well each explains the target's one-step motion (dynamics consistency,
:func:`dynamics_consistency`). The map it returns is an
:class:`~tatl_mj.transfer.intertask_mapping.AffineMapping`.
"""

from __future__ import annotations

import dataclasses
import itertools
from typing import Any, Callable, ClassVar

import numpy as np

from tatl_mj.transfer.features import periodic_mask, wrap_angle
from tatl_mj.transfer.intertask_mapping import AffineMapping, Mapping
from tatl_mj.transfer.manifold_alignment import LinearAlignment, align_manifolds, standardiser
from tatl_mj.transitions import Transitions
from tatl_mj.validation import Boolean, Constraints, Interval, ListOf, check_settings, integer

SourceStep = Callable[[np.ndarray, np.ndarray], np.ndarray]


def _unwrapped(t: Transitions, mask: tuple[bool, ...] | None) -> Transitions:
    """``t`` with next states written as ``s + wrapped increment``, so increments are the motion."""
    return dataclasses.replace(t, next_states=t.states + _wrap(t.next_states - t.states, mask))


def _subset(t: Transitions, idx: np.ndarray) -> Transitions:
    return Transitions(*(getattr(t, f.name)[idx] for f in dataclasses.fields(Transitions)))


def _wrap(increments: np.ndarray, periodic: tuple[bool, ...] | None) -> np.ndarray:
    """Increments with the angle coordinates (``periodic``) wrapped into [-pi, pi)."""
    if periodic is None:
        return increments
    wrapped = increments.copy()
    mask = np.asarray(periodic)
    wrapped[:, mask] = wrap_angle(wrapped[:, mask])
    return wrapped


def _consistency(
    mapping: Mapping,
    target: Transitions,
    source_step: SourceStep,
    scale: np.ndarray | None,
    rate: float | None,
    source_mask: tuple[bool, ...] | None,
    target_mask: tuple[bool, ...] | None,
) -> tuple[float, float]:
    """(score, rate) of :func:`dynamics_consistency`, the rate fitted when None."""
    x = mapping.chi_plus(target.states)
    source_increment = _wrap(source_step(x, target.actions) - x, source_mask)
    # A mapping that wraps its images (e.g. InCoordinates) jumps by 2 pi where a
    # step crosses the cut; the motion is the wrapped difference.
    mapped = _wrap(mapping.chi(x + source_increment) - mapping.chi(x), target_mask)
    observed = _wrap(target.next_states - target.states, target_mask)
    scale = np.maximum(observed.std(axis=0) if scale is None else np.asarray(scale, np.float64), 1e-12)
    mapped, observed = mapped / scale, observed / scale
    if rate is None:
        rate = max(float(np.sum(mapped * observed) / max(np.sum(mapped * mapped), 1e-300)), 0.0)
    return float(np.mean((observed - rate * mapped) ** 2)), float(rate)


def dynamics_consistency(
    mapping: Mapping,
    target: Transitions,
    source_step: SourceStep,
    scale: np.ndarray | None = None,
    rate: float | None = 1.0,
    source_periodic: tuple[bool, ...] | None = None,
    target_periodic: tuple[bool, ...] | None = None,
) -> float:
    """How well the source simulator, seen through the mapping, predicts target transitions.

    The mean squared difference, per coordinate, between the target increment
    ``s'_T - s_T`` and ``rate`` times the mapped source increment
    ``chi(x + P_S(x, a) - x) - chi(x)`` with ``x = chi_plus(s_T)`` (actions matched
    by index). Increments of the coordinates flagged ``*_periodic`` are wrapped
    into [-pi, pi): the source's before it is mapped, the target's and the
    mapped one after, so a step across +-pi counts as the short motion it is.
    Each coordinate is divided by ``scale`` (default: the standard deviation of
    the target's increments), so 1.0 is as good as predicting "no change".
    ``rate`` is how many source steps one target step spans; None fits it
    (least squares, >= 0), since two domains' control steps need not cover the
    same stretch of their motion and a state map cannot absorb that.
    """
    source_mask = periodic_mask(source_periodic, None, "source_periodic")
    target_mask = periodic_mask(target_periodic, target.state_dim, "target_periodic")
    return _consistency(mapping, target, source_step, scale, rate, source_mask, target_mask)[0]


@dataclasses.dataclass(frozen=True)
class TransitionAlignment:
    """Settings of :func:`align_transitions` (``mapping.kind = "transition_alignment"``).

    Attributes:
      n_neighbors: neighbourhood size of the state-only candidates (:func:`align_manifolds`).
      mu: correspondence weight of the state-only candidates.
      max_samples: each side is subsampled to at most this many transitions.
      rates: time-rate factors (target steps per source step) tried for the
        model-consistent candidates; the control steps of two domains need not
        cover the same stretch of their motion.
      sign_flips: also try the state-only alignment with each shared coordinate's
        sign flipped (2^d candidates, d <= 6).
    """

    n_neighbors: int = 8
    mu: float = 1.0
    max_samples: int = 1500
    rates: tuple[float, ...] = tuple(float(r) for r in np.geomspace(0.125, 8.0, 13))
    sign_flips: bool = True

    constraints: ClassVar[Constraints] = {
        "n_neighbors": [Interval(int, 2)],
        "mu": [Interval(float, 0, closed="right")],
        "max_samples": [Interval(int, 10)],
        "rates": [ListOf(Interval(float, 0, closed="right"), nonempty=True)],
        "sign_flips": [Boolean()],
    }

    def __post_init__(self) -> None:
        check_settings(self)

    @staticmethod
    def from_dict(table: dict[str, Any]) -> "TransitionAlignment":
        """Settings from a spec table; unknown keys are refused, naming the valid ones."""
        valid = [f.name for f in dataclasses.fields(TransitionAlignment)]
        unknown = sorted(set(table) - set(valid))
        if unknown:
            raise ValueError(f"unknown transition_alignment setting(s) {unknown}; valid: {valid}")
        return TransitionAlignment(**table)


@dataclasses.dataclass(frozen=True, eq=False)
class _IncrementModel:
    """Least-squares ``z' - z = F z + e[a]`` in standardised coordinates ``z = (s - mean) @ white.T``.

    One state matrix and one offset per action index rather than ``B u``: that
    needs no assumption on how two tasks' action values compare, only
    Assumption 1 (actions matched by index).
    """

    mean: np.ndarray
    white: np.ndarray
    f: np.ndarray  # (d, d)
    e: np.ndarray  # (n_actions, d)

    @staticmethod
    def fit(t: Transitions, n_actions: int, name: str) -> "_IncrementModel":
        mean, white = standardiser(t.states, f"{name}.states", True)
        z, z_next = (t.states - mean) @ white.T, (t.next_states - mean) @ white.T
        design = np.hstack([z, np.eye(n_actions)[t.actions]])
        theta, *_ = np.linalg.lstsq(design, z_next - z, rcond=None)
        return _IncrementModel(mean, white, theta[: z.shape[1]].T, theta[z.shape[1] :])

    def step(self, states: np.ndarray, actions: np.ndarray) -> np.ndarray:
        z = (states - self.mean) @ self.white.T
        return (z + z @ self.f.T + self.e[actions]) @ np.linalg.inv(self.white).T + self.mean


def _consistent_map(f_s, e_s, f_t, e_t) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares (M, m) with ``s_T = M s_S + m`` carrying the source model onto the target's.

    Substituting the map into both increment models gives conditions linear in
    (M, m): ``M F_S = F_T M`` and ``M e_S[i] = F_T m + e_T[i]`` for every action i.
    For a controllable linear system they fix M uniquely (the state-space
    similarity transform between two realisations of one input-output map,
    ``M = C_T C_S^-1`` with C the controllability matrices). Each block is scaled
    by the size of its target-side terms so neither dominates by units alone.
    """
    d_t, d_s = f_t.shape[0], f_s.shape[0]
    n_m = d_t * d_s
    # vec is row-major: M.ravel()[i * d_s + j] = M[i, j].
    sylvester = np.kron(f_t, np.eye(d_s)) - np.kron(np.eye(d_t), f_s.T)  # vec(F_T M - M F_S)
    rows = [np.hstack([sylvester, np.zeros((n_m, d_t))]) / max(np.linalg.norm(f_t), 1e-12)]
    rhs = [np.zeros(n_m)]
    scale = max(np.linalg.norm(e_t), 1e-12)
    for es, et in zip(e_s, e_t):
        rows.append(np.hstack([np.kron(np.eye(d_t), es[None, :]), -f_t]) / scale)
        rhs.append(et / scale)
    solution, *_ = np.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), rcond=None)
    return solution[:n_m].reshape(d_t, d_s), solution[n_m:]


def _model_candidates(
    source: _IncrementModel,
    target: _IncrementModel,
    rates: tuple[float, ...],
) -> list[tuple[str, AffineMapping]]:
    """One affine map per rate factor: the map that makes the two increment models agree."""
    unwhite_t = np.linalg.inv(target.white)
    candidates = []
    for rate in rates:
        m_z, o_z = _consistent_map(rate * source.f, rate * source.e, target.f, target.e)
        # z_T = m_z z_S + o_z, written in state units.
        matrix = unwhite_t @ m_z @ source.white
        candidates.append(
            (f"model rate {rate:.4g}", AffineMapping(matrix, target.mean + unwhite_t @ o_z - matrix @ source.mean))
        )
    return candidates


def _sign_flip_candidates(shared: LinearAlignment) -> list[tuple[str, AffineMapping]]:
    """The state-only alignment with each shared coordinate's sign flipped (2^d maps).

    Flipping shared coordinate k on one side only (alpha's column k) composes chi
    with a reflection: ``chi_z = pinv(beta^T) diag(signs) alpha^T``; all signs +1
    is the original. These are the ambiguities local geometry cannot resolve.
    """
    candidates = []
    for signs in itertools.product((1.0, -1.0), repeat=shared.alpha.shape[1]):
        m_z = np.linalg.pinv(shared.beta.T) @ (np.asarray(signs)[:, None] * shared.alpha.T)
        matrix = np.linalg.inv(shared.target_whitener) @ m_z @ shared.source_whitener
        candidates.append(
            (
                f"states signs {[int(s) for s in signs]}",
                AffineMapping(matrix, shared.target_mean - matrix @ shared.source_mean),
            )
        )
    return candidates


def _checked_pair(
    source: Transitions,
    target: Transitions,
    n_source_actions: int,
    n_target_actions: int,
) -> int:
    """Validates the two batches against Assumption 1; returns the shared action count."""
    for name, value in (("source", source), ("target", target)):
        if not isinstance(value, Transitions):
            raise ValueError(f"{name} must be a Transitions batch, got {type(value).__name__}")
    n_s = integer("", "n_source_actions", n_source_actions, 2)
    n_t = integer("", "n_target_actions", n_target_actions, 2)
    if n_s != n_t:
        raise ValueError(
            "n_source_actions and n_target_actions must be the same number of actions "
            f"(Assumption 1: matched by index), got {n_s} and {n_t}"
        )
    for name, value in (("source", source), ("target", target)):
        if value.actions.min() < 0 or value.actions.max() >= n_s:
            raise ValueError(f"{name}.actions must index the {n_s} actions (0..{n_s - 1})")
    return n_s


def align_transitions(
    source: Transitions,
    target: Transitions,
    n_source_actions: int,
    n_target_actions: int,
    *,
    source_periodic: tuple[bool, ...] | None = None,
    target_periodic: tuple[bool, ...] | None = None,
    source_step: SourceStep | None = None,
    settings: TransitionAlignment = TransitionAlignment(),
    rng: np.random.Generator | None = None,
) -> tuple[AffineMapping, dict[str, Any]]:
    """A state mapping from random transitions of both tasks, chosen by dynamics consistency.

    State samples alone leave a map defined only up to the symmetries of the
    sample clouds (a random policy's data are symmetric: s and -s are equally
    likely), so :func:`align_manifolds` cannot tell chi from -chi. The dynamics
    can: with actions matched by index (the paper's Assumption 1), a map that
    flips the sign of the state also has to flip the effect of each action.
    Ammar et al. (AAAI 2015) therefore align (s, a, s') triplets; here the
    triplets choose among candidate state maps by dynamics consistency (the
    source simulator, seen through the map, should reproduce the target's
    transitions, as TA-TL's Algorithm 1 assumes when it queries it):

    1. Candidates: (a) for each time-rate factor in ``settings.rates``, the
       affine map that makes the two tasks' least-squares linear increment models
       agree (``_model_candidates``); (b) the state-only alignment with each
       shared coordinate's sign flipped (``_sign_flip_candidates``).
    2. Keep the candidate with the least :func:`dynamics_consistency` (rate
       fitted) on the target transitions, stepping with ``source_step`` (e.g. the
       source simulator; default: the source's fitted linear model).

    The map is affine in the coordinates the batches are given in; for a
    periodic coordinate cut in the wrong place use
    :func:`tatl_mj.transfer.coordinates.align_in_coordinates`.

    Args:
      source, target: random-policy transitions of each task.
      n_source_actions, n_target_actions: each task's number of discrete actions;
        they must agree (actions are matched by index).
      source_periodic, target_periodic: optional per-coordinate flags of angles,
        whose increments are wrapped into [-pi, pi) (a pendulum passing +-pi).
      source_step: batched source step (N, dS), (N,) action indices -> (N, dS).
      settings: :class:`TransitionAlignment`.
      rng: draws subsamples of sets larger than ``settings.max_samples``.

    Returns:
      The chosen :class:`AffineMapping` (chi: source -> target) and its record
      for the run's files: ``matrix``, ``offset`` (lists), ``candidate`` (which
      one won), ``rate`` (fitted target steps per source step), ``consistency``
      (its score) and ``candidates`` (the number compared).
    """
    n_actions = _checked_pair(source, target, n_source_actions, n_target_actions)
    if not isinstance(settings, TransitionAlignment):
        raise ValueError(f"settings must be a TransitionAlignment, got {type(settings).__name__}")
    masks = (
        periodic_mask(source_periodic, source.state_dim, "source_periodic"),
        periodic_mask(target_periodic, target.state_dim, "target_periodic"),
    )
    source, target = _unwrapped(source, masks[0]), _unwrapped(target, masks[1])
    rng = rng if rng is not None else np.random.default_rng(0)
    source = _at_most(source, settings.max_samples, rng)
    target = _at_most(target, settings.max_samples, rng)

    source_model = _IncrementModel.fit(source, n_actions, "source")
    candidates = _transition_candidates(source, target, source_model, n_actions, settings, rng)
    step = source_step if source_step is not None else source_model.step
    best, (score, rate) = _most_consistent(candidates, target, step, masks)
    label, mapping = candidates[best]
    record = {
        "kind": "transition_alignment",
        "matrix": mapping.matrix.tolist(),
        "offset": mapping.offset.tolist(),
        "candidate": label,
        "rate": rate,
        "consistency": score,
        "candidates": len(candidates),
    }
    return mapping, record


def _at_most(t: Transitions, n: int, rng: np.random.Generator) -> Transitions:
    """``t``, or a random ``n`` of its transitions (without replacement) when it has more."""
    if len(t) > n:
        return _subset(t, rng.choice(len(t), n, replace=False))
    return t


def _transition_candidates(
    source: Transitions,
    target: Transitions,
    source_model: _IncrementModel,
    n_actions: int,
    settings: TransitionAlignment,
    rng: np.random.Generator,
) -> list[tuple[str, AffineMapping]]:
    """The labelled candidate maps :func:`align_transitions` chooses among (its step 1)."""
    candidates = _model_candidates(source_model, _IncrementModel.fit(target, n_actions, "target"), settings.rates)
    if settings.sign_flips and min(source.state_dim, target.state_dim) <= 6:
        shared = align_manifolds(
            source.states,
            target.states,
            n_neighbors=settings.n_neighbors,
            mu=settings.mu,
            rng=rng,
            max_samples=settings.max_samples,
        )
        candidates += _sign_flip_candidates(shared)
    return candidates


def _most_consistent(
    candidates: list[tuple[str, AffineMapping]],
    target: Transitions,
    step: SourceStep,
    masks: tuple[tuple[bool, ...] | None, tuple[bool, ...] | None],
) -> tuple[int, tuple[float, float]]:
    """The index of the candidate with the least dynamics inconsistency on ``target``, and its
    (score, fitted rate); a candidate whose mapped states ``step`` rejects scores infinite."""
    scores = []
    for _, candidate in candidates:
        try:
            scores.append(_consistency(candidate, target, step, None, None, *masks))
        except ValueError:  # e.g. a mapped state the source simulator rejects
            scores.append((np.inf, 0.0))
    best = int(np.argmin([score for score, _ in scores]))
    if not np.isfinite(scores[best][0]):
        raise ValueError("align_transitions: the source step rejected every candidate map's states")
    return best, scores[best]


__all__ = [
    "SourceStep",
    "TransitionAlignment",
    "align_transitions",
    "dynamics_consistency",
]
