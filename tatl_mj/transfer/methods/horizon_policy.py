"""The horizon TA-TL policy: Algorithm 1's adaptation over H target steps instead of one.

Where this departs from the paper, and why. Algorithm 1 (``transfer/algorithm1.py``) picks the action
that makes the apprentice land on the projected source *next* state. When the target's
actuator reaches the coordinates that matter only through other states (the bicycle:
handlebar torque moves the steer rate within one 10 ms step, the roll only over
100-400 ms), that one-step match is a servo on the wrong coordinates. Here the same
idea is applied over a horizon of H target steps with one action held throughout:

1. ``x_0 = chi_plus(s_T)``; roll the greedy source policy ``x_k = P_S(x_{k-1},
   argmax_a Q_S(x_{k-1}, a))`` for ``K = ceil(H / rho)`` source steps, where
   ``rho = dt_source / dt_target`` is the step ratio (cart-pole 20 ms, bicycle 10 ms:
   rho = 2, so source step k is target step 2k).
2. References ``r_j`` for target steps j = 1..H: ``chi`` of the source trajectory at
   source time ``t = j / rho``, linearly interpolated between ``chi(x_floor(t))`` and
   ``chi(x_ceil(t))`` (on periodic coordinates along the shorter arc). With an integer
   rho the shared times ``j = rho k`` get ``chi(x_k)`` exactly and the steps in
   between the chord; a non-integer rho needs no special case.
   With ``reference="zero"`` the references are all 0 (the ``apprentice-upright``
   ablation: the same controller aiming at the target's zero state, no source at all).
   ``source_zero`` names source coordinates set to 0 in ``x_0`` before the rollout
   (an ablation that shows which part of the source's state makes the reference
   worse than upright: e.g. the cart's position and velocity, which the cart-pole
   policy also steers back to centre).
3. Nominal action ``a_0``: the target action of the first greedy source action's
   index, ``target_actions[a_S]`` (Assumption 1, as Algorithm 1's a_T), or
   ``clip(0, low, high)`` for the zero reference.
4. Free response ``F_j``: the model rolled j steps from s_T with a_0 held; control
   response ``G_j`` (d x m): the finite difference of that rollout when column i of
   the held action moves by ``delta_i``. For j = 1 and a model affine in the action
   (the apprentice) ``G_1 = B_hat`` exactly; for j > 1 it is exact when the drift is
   linear too, and a secant of width delta otherwise.
5. ``a = clip(a_0 + argmin_D sum_j |W^(1/2) (F_j + G_j D - r_j)|^2, low, high)`` with
   W = diag(weights), solved as one stacked least-squares problem per state by SVD
   (the minimum-norm D when the weighted responses do not determine it, e.g. weights
   only on a coordinate the action cannot reach within H steps: then D = 0).

With H = 1, rho = 1 and W = I this is Algorithm 1 term for term: ``F_1 = P_hat(s_T,
a_T)``, ``G_1 = B_hat``, ``r_1 = s_hat_T_next`` and ``D = pinv(B_hat) (r_1 - F_1) = K
pi_ad`` (the least-squares minimiser of ``|P_hat(s, a) - s_hat_T_next|`` is what pinv
gives), so the two policies agree up to float rounding (tests check it).

The target model is any batched one-step function ``model(states (N, d), action_values
(N, m)) -> (N, d)``: ``apprentice.predict`` for horizon TA-TL, the true simulator
(actuator values in) for the oracle ablation. Differences on the ``periodic``
coordinates (pass ``apprentice.periodic``) are taken the shorter way round.

Wiring (horizon TA-TL and its two ablations are one class with different settings; the
method that builds them is ``methods/horizon.py``, the oracle's model ``methods/linearisation.py``):

- horizon TA-TL: ``HorizonTATLPolicy(apprentice.predict, low, high, horizon=round(T_h /
  dt_T), step_ratio=dt_S / dt_T, weights=w, source_q=q, mapping=chi, source_step=P_S,
  target_actions=values, periodic=apprentice.periodic, samples_used=n)``;
- ``apprentice-upright``: the same with ``reference="zero"`` and no source fields;
- oracle: ``model`` = the true target step taking actuator values. A simulator that draws
  noise per call gives the nominal and probe rollouts different noise; seed it the same
  for every call (or switch the noise off) so G_j measures the action alone.

Several policies that differ only in their model decide together (:func:`shared_decisions`,
the method contract's ``decide_together`` hook): a learning curve's budgets in one batch.

Pure numpy: nothing here imports mujoco or a suite domain.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Callable, ClassVar, Sequence

import numpy as np

from tatl_mj.transfer.algorithm1 import PremiseStep, SourceStep
from tatl_mj.transfer.features import Periodic, as_states, periodic_difference
from tatl_mj.transfer.fqi import QFunction
from tatl_mj.transfer.intertask_mapping import Mapping
from tatl_mj.transfer.method import JointDecisions, JointPremises
from tatl_mj.transfer.methods.linearisation import TargetModel
from tatl_mj.validation import (
    Array,
    Constraints,
    Function,
    Interval,
    InvalidSetting,
    ListOf,
    Options,
    check_settings,
)

REFERENCES = ("source", "zero")

_EPS = 1e-9  # tolerance on source times j / rho, so rho = 0.02 / 0.01 lands on integers


@dataclasses.dataclass(frozen=True)
class HorizonStep:
    """Every quantity of one horizon TA-TL decision (batched over N target states).

    The source fields are None for the zero reference.
    """

    s_T: np.ndarray  # (N, dT) target states
    s_hat_S: np.ndarray | None  # (N, dS) chi_plus(s_T), the source rollout's start x_0
    a_S: np.ndarray | None  # (N,) greedy source action index at x_0
    source_states: np.ndarray | None  # (N, K + 1, dS) source rollout x_0..x_K
    references: np.ndarray  # (N, H, dT) r_j, j = 1..H
    nominal: np.ndarray  # (N, mT) a_0, the held action the responses are taken about
    free: np.ndarray  # (N, H, dT) F_j, the model's rollout with a_0 held
    control: np.ndarray  # (N, H, dT, mT) G_j, d F_j / d a (finite differences)
    adaptive: np.ndarray  # (N, mT) D, the weighted least-squares correction
    action: np.ndarray  # (N, mT) clip(a_0 + D, low, high)


def _least_squares(rows: np.ndarray, rhs: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Minimum-norm x of |rows x - rhs| per state: (N, p, m), (N, p), (N,) -> (N, m).

    ``pinv``'s cutoff is relative to the largest singular value, so a response that is
    zero up to rounding (1e-16, an unactuated coordinate) would be inverted into a huge
    action; the cutoff here is relative to the unweighted response size ``scale``.
    """
    u, sv, vt = np.linalg.svd(rows, full_matrices=False)
    keep = sv > 1e-10 * scale[:, None]
    inverse = np.where(keep, 1.0 / np.where(keep, sv, 1.0), 0.0)
    coeffs = inverse * np.einsum("npk,np->nk", u, rhs)
    return np.einsum("nkm,nk->nm", vt, coeffs)


@dataclasses.dataclass(frozen=True, eq=False)
class HorizonTATLPolicy:
    """Horizon-matched TA-TL (see the module docstring for the algorithm).

    Attributes:
      model: the target model, (N, dT) states, (N, mT) action values -> (N, dT).
      target_low, target_high: (mT,) actuator limits; the action is clipped to them.
      horizon: H, target steps matched (e.g. 20 for 200 ms of 10 ms bicycle steps).
      step_ratio: rho = dt_source / dt_target (> 0; 2 for cart-pole -> bicycle).
      weights: (dT,) diagonal of W, >= 0 and not all 0; None means all ones.
      reference: "source" (the projected source rollout) or "zero" (aim at the zero
        state; the source fields are then not used and may be None).
      source_q, mapping, source_step, target_actions: Q_S, chi / chi_plus, P_S and the
        (n, mT) target action values of the source's n action indices; required for
        ``reference="source"``.
      periodic: (dT,) bools marking angle coordinates (``apprentice.periodic``).
      source_zero: indices of source coordinates set to 0 in x_0 = chi_plus(s_T) before
        the source rollout (empty: none).
      affine: optional (A, B, c) such that ``model(s, a) = A s + B a + c`` exactly (an
        apprentice with linear features, :meth:`Apprentice.affine`; the oracle's
        linearisation). F_j and G_j then come in closed form from powers of A instead
        of H model calls: the same numbers up to rounding, a fraction of the time.
      delta: (mT,) finite-difference probe in actuator units (> 0); None means 10% of
        the actuator range (1 where the range is unbounded). The probe goes towards the
        inside of the range, so a clipping simulator sees the perturbation.
      samples_used: target samples the model used, for reports (as TATLPolicy's).
      admissible: optional (n_ad, mT) action set the clipped action is snapped to
        (its nearest row), e.g. the target's discrete actions.
    """

    model: TargetModel
    target_low: np.ndarray
    target_high: np.ndarray
    horizon: int = 1
    step_ratio: float = 1.0
    weights: np.ndarray | None = None
    reference: str = "source"
    source_q: QFunction | None = None
    mapping: Mapping | None = None
    source_step: SourceStep | None = None
    target_actions: np.ndarray | None = None
    periodic: tuple[bool, ...] | None = None
    source_zero: tuple[int, ...] = ()
    affine: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    delta: np.ndarray | None = None
    samples_used: int | None = None
    admissible: np.ndarray | None = None

    constraints: ClassVar[Constraints] = {
        "model": [Function("(states (N, d), action values (N, m)) -> (N, d)")],
        "target_low": [Array(1, finite=False)],
        "target_high": [Array(1, finite=False)],
        "horizon": [Interval(int, 1, unit=" (target steps)")],
        "step_ratio": [Interval(float, 0, closed="right", unit=" (dt_source / dt_target)")],
        "weights": [None, Array(1, low=0, not_all_zero=True)],
        "reference": [Options(*REFERENCES)],
        "source_step": [None, Function("(states (N, dS), action indices (N,)) -> (N, dS)")],
        "target_actions": [None, Array(2)],
        "periodic": [None, Periodic()],
        "source_zero": [ListOf(Interval(int, 0))],
        "delta": [None, Array(1, low=0, low_open=True)],
        "admissible": [None, Array(2)],
    }

    def __post_init__(self) -> None:
        check_settings(self)
        owner, low, high = type(self).__name__, self.target_low, self.target_high
        m = low.size
        if high.shape != low.shape or np.any(low > high):
            raise InvalidSetting(
                f"{owner}.target_low must be <= target_high, one entry per action column each, got {low} and {high}"
            )
        if self.reference == "source":
            missing = [n for n in ("source_q", "mapping", "source_step", "target_actions") if getattr(self, n) is None]
            if missing:
                raise InvalidSetting(
                    f"{owner}: reference='source' needs {', '.join(missing)} (or use reference='zero')"
                )
            if self.source_q.n_actions != len(self.target_actions):
                raise InvalidSetting(
                    f"{owner}: source_q has {self.source_q.n_actions} actions, target_actions has "
                    f"{len(self.target_actions)} (Assumption 1)"
                )
        elif self.source_zero:
            raise InvalidSetting(f"{owner}.source_zero must be empty with reference='zero', got {self.source_zero}")
        for field in ("target_actions", "admissible"):
            value = getattr(self, field)
            if value is not None and value.shape[1] != m:
                raise InvalidSetting(
                    f"{owner}.{field} must have {m} columns (one per action column), got {value.shape}"
                )
        if self.delta is not None and self.delta.size not in (1, m):
            raise InvalidSetting(f"{owner}.delta must have one or {m} entries, got {self.delta.size}")
        if self.affine is not None:
            if self.periodic is not None:
                raise InvalidSetting(f"{owner}.affine (closed-form responses) cannot be used with periodic coordinates")
            self._affine_responses  # noqa: B018 (derived now, so that a malformed affine is refused here)

    @functools.cached_property
    def _probe(self) -> np.ndarray:
        """(mT,) the finite-difference probe of each action column: ``delta``, or 10% of the range."""
        span = self.target_high - self.target_low
        delta = np.where(np.isfinite(span) & (span > 0), 0.1 * span, 1.0) if self.delta is None else self.delta
        return np.broadcast_to(delta.ravel(), span.shape).copy()

    @functools.cached_property
    def _affine_responses(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """F_j's and G_j's parts for an ``affine`` model (:func:`_closed_form`)."""
        assert self.affine is not None
        return _closed_form(self.affine, self.horizon, self.target_low.size)

    @property
    def source_steps(self) -> int:
        """K = ceil(H / rho), the source steps rolled per decision."""
        return max(1, math.ceil(self.horizon / self.step_ratio - _EPS))

    def _source_references(self, s_T: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """x_0, a_S, the source rollout (N, K + 1, dS) and the references (N, H, dT)."""
        x = self.mapping.chi_plus(s_T)
        if self.source_zero:
            if max(self.source_zero) >= x.shape[1]:
                raise ValueError(f"source_zero {self.source_zero} out of range for {x.shape[1]} source coordinates")
            x = x.copy()
            x[:, list(self.source_zero)] = 0.0
        s_hat_S = x
        rollout = [x]
        a_S = None
        for _ in range(self.source_steps):
            a = np.asarray(self.source_q.greedy(x), dtype=np.int64)
            a_S = a if a_S is None else a_S
            x = np.asarray(self.source_step(x, a), dtype=np.float64)
            if x.shape != s_hat_S.shape:
                raise ValueError(f"source_step returned shape {x.shape}, expected {s_hat_S.shape}")
            rollout.append(x)
        source_states = np.stack(rollout, axis=1)  # (N, K + 1, dS)
        n, k1, d_s = source_states.shape
        mapped = self.mapping.chi(source_states.reshape(n * k1, d_s)).reshape(n, k1, -1)
        if mapped.shape[2] != s_T.shape[1]:
            raise ValueError(f"mapping.chi gives {mapped.shape[2]} target coordinates, states have {s_T.shape[1]}")
        # Source time of target step j is j / rho; interpolate between its neighbours.
        t = np.arange(1, self.horizon + 1) / self.step_ratio
        k0 = np.minimum(np.floor(t + _EPS).astype(np.int64), k1 - 1)
        k_1 = np.minimum(k0 + 1, k1 - 1)
        frac = np.clip(t - k0, 0.0, 1.0)
        frac[np.abs(frac) < _EPS] = 0.0  # shared times take chi(x_k) itself
        lo, hi = mapped[:, k0], mapped[:, k_1]
        references = lo + frac[None, :, None] * periodic_difference(hi, lo, self.periodic)
        return s_hat_S, a_S, source_states, references

    def _responses(self, s_T: np.ndarray, nominal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """F (N, H, d) with a_0 held, and G (N, H, d, m): closed forms, or finite differences."""
        n, d = s_T.shape
        m = nominal.shape[1]
        if self.affine is not None:
            powers, sums, control, c, b = self._affine_responses
            if powers.shape[1] != d:
                raise ValueError(f"affine model has {powers.shape[1]} coordinates, states have {d}")
            # F_j = A^j s + (sum_{i<j} A^i)(B a_0 + c)
            free = np.einsum("jde,ne->njd", powers, s_T) + np.einsum("jde,ne->njd", sums, nominal @ b.T + c)
            return free, np.broadcast_to(control, (n, *control.shape))
        # Probe towards the inside of the actuator range so a clipping model responds.
        probe = self._probe
        step = np.where(nominal + probe <= self.target_high, probe, -probe)  # (N, m)
        actions = np.repeat(nominal[None], m + 1, axis=0)  # block 0 nominal, block i+1 probes column i
        for i in range(m):
            actions[i + 1, :, i] += step[:, i]
        actions = actions.reshape((m + 1) * n, m)
        states = np.tile(s_T, (m + 1, 1))
        path = np.empty((self.horizon, m + 1, n, d))
        for j in range(self.horizon):
            states = np.asarray(self.model(states, actions), dtype=np.float64)
            if states.shape != ((m + 1) * n, d):
                raise ValueError(f"model returned shape {states.shape}, expected {((m + 1) * n, d)}")
            path[j] = states.reshape(m + 1, n, d)
        free = path[:, 0].transpose(1, 0, 2)  # (N, H, d)
        moved = periodic_difference(path[:, 1:], path[:, :1], self.periodic)  # (H, m, N, d)
        control = moved.transpose(2, 0, 3, 1) / step[:, None, None, :]  # (N, H, d, m)
        return free, control

    def step(self, target_states: np.ndarray) -> HorizonStep:
        """One decision for (N, dT) target states, with every intermediate."""
        s_T = as_states(target_states, "target_states")
        self._check_coordinates(s_T.shape[1])
        s_hat_S, a_S, source_states, references = self._references(s_T)
        nominal = self._nominal(len(s_T), a_S)
        free, control = self._responses(s_T, nominal)
        adaptive, action = self._correction(references, nominal, free, control)
        return HorizonStep(s_T, s_hat_S, a_S, source_states, references, nominal, free, control, adaptive, action)

    def _references(
        self, s_T: np.ndarray
    ) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None, np.ndarray]:
        """x_0, a_S, the source rollout and the references (N, H, dT); the source parts
        are None for the zero reference, whose references are all 0."""
        if self.reference == "source":
            return self._source_references(s_T)
        return None, None, None, np.zeros((len(s_T), self.horizon, s_T.shape[1]))

    def _check_coordinates(self, d: int) -> None:
        if self.weights is not None and self.weights.size != d:
            raise ValueError(f"weights has {self.weights.size} entries, target states have {d} coordinates")
        if self.periodic is not None and len(self.periodic) != d:
            raise ValueError(f"periodic has {len(self.periodic)} entries, target states have {d} coordinates")

    def _nominal(self, n: int, a_S: np.ndarray | None) -> np.ndarray:
        """a_0 (N, mT): the source's first action seen in the target, or the clipped zero."""
        if self.reference == "source":
            return self.target_actions[a_S]
        return np.broadcast_to(np.clip(0.0, self.target_low, self.target_high), (n, self.target_low.size)).copy()

    def _correction(
        self, references: np.ndarray, nominal: np.ndarray, free: np.ndarray, control: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """D and the clipped (snapped) action from the responses: each row on its own."""
        n, _, d = free.shape
        m = nominal.shape[1]
        root = np.sqrt(np.ones(d) if self.weights is None else self.weights)
        gap = root * periodic_difference(free, references, self.periodic)  # (N, H, d)
        rows = (root[None, None, :, None] * control).reshape(n, self.horizon * d, m)
        adaptive = -_least_squares(
            rows, gap.reshape(n, self.horizon * d), root.max() * np.abs(control).max(axis=(1, 2, 3))
        )
        action = np.clip(nominal + adaptive, self.target_low, self.target_high)
        if self.admissible is not None:
            gaps = np.linalg.norm(action[:, None, :] - self.admissible[None, :, :], axis=2)
            action = self.admissible[np.argmin(gaps, axis=1)]
        return adaptive, action

    def __call__(self, target_states: np.ndarray) -> np.ndarray:
        """(N, dT) target states -> (N, mT) target action values."""
        return self.step(target_states).action

    premise_measures: ClassVar[tuple[str, ...]] = ("delta", "infeasible", "round_trip")
    """The premises measured for it (``run.premises.measures_of``): its model's one-step
    error, the request's feasibility and the mapping's round trip (no apprentice B_hat
    or one-step tracking: the rule matches a horizon, not B_hat's one step)."""

    def premise_step(self, target_states: np.ndarray) -> PremiseStep:
        """The method contract's ``premise_step`` hook: the same decision as ``__call__``
        (one :meth:`step`), with the request ``a_0 + D`` before clipping and the model's
        next state for the action taken."""
        step = self.step(target_states)
        return self._premise(step.s_T, step.nominal + step.adaptive, step.action)

    def _premise(self, s_T: np.ndarray, requested: np.ndarray, action: np.ndarray) -> PremiseStep:
        return PremiseStep(action, requested, None, np.asarray(self.model(s_T, action), dtype=np.float64))

    def decide_together(self, policies: Sequence[object]) -> JointDecisions | None:
        """The method contract's ``decide_together`` hook (``tatl_mj.transfer.method``),
        called on the first of ``policies``: :func:`shared_decisions`."""
        return shared_decisions(list(policies))

    def premise_together(self, policies: Sequence[object]) -> JointPremises | None:
        """The method contract's ``premise_together`` hook: :func:`shared_premises`."""
        return shared_premises(list(policies))


_SOURCE_SIDE = ("source_q", "mapping", "source_step", "source_zero", "step_ratio")
# What a decision's correction depends on besides the responses: equal across the
# budgets of one unit, which differ in their model (the apprentice) alone.
_CONTROLLER_SIDE = ("target_low", "target_high", "horizon", "weights", "reference", "periodic", "admissible")


def _same(policy: object, first: object, fields: tuple[str, ...]) -> bool:
    return all(
        getattr(policy, f) is getattr(first, f) or np.array_equal(getattr(policy, f), getattr(first, f)) for f in fields
    )


def _decide_together(policy: object, first: object) -> bool:
    if not (isinstance(policy, HorizonTATLPolicy) and isinstance(first, HorizonTATLPolicy)):
        return False
    if not _same(policy, first, _CONTROLLER_SIDE):
        return False
    return first.reference == "zero" or (
        _same(policy, first, _SOURCE_SIDE) and np.array_equal(policy.target_actions, first.target_actions)
    )


def shared_decisions(policies: list) -> JointDecisions | None:
    """Several horizon policies' decisions for all their states at once, or None.

    The budgets of one horizon TA-TL unit share the source side (Q_S, chi, P_S, rho)
    and the controller (H, W, limits) and differ in the model (the apprentice). A row's
    decision does not depend on the other rows, so every policy's states take one
    source rollout (a tenth of the source queries) and one correction; only the
    responses are each policy's own. None unless there are several such policies.
    """
    joint = _joint(policies)
    if joint is None:
        return None

    def decide(blocks: list[int], states: list[np.ndarray]) -> list[np.ndarray]:
        _, _, action, spans = joint(blocks, states)
        return [action[a:z] for a, z in spans]

    return decide


def shared_premises(policies: list) -> JointPremises | None:
    """:func:`shared_decisions` with each block's :class:`PremiseStep`: the same computation,
    so each step's action is bit for bit the joint decision (its model's prediction is
    taken afterwards, for the premises alone). None where :func:`shared_decisions` is."""
    joint = _joint(policies)
    if joint is None:
        return None

    def steps(blocks: list[int], states: list[np.ndarray]) -> list[PremiseStep]:
        s_T, requested, action, spans = joint(blocks, states)
        return [policies[b]._premise(s_T[a:z], requested[a:z], action[a:z]) for b, (a, z) in zip(blocks, spans)]

    return steps


def _joint(policies: list) -> Callable | None:
    """The shared decision: (blocks, states) -> s_T, the requests a_0 + D, the actions, and
    each block's (start, end) rows; None unless there are several such policies."""
    if len(policies) < 2 or not all(_decide_together(p, policies[0]) for p in policies):
        return None
    first = policies[0]

    def joint(
        blocks: list[int], states: list[np.ndarray]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[tuple[int, int]]]:
        rows = [as_states(s, "target_states") for s in states]
        s_T = np.concatenate(rows)
        first._check_coordinates(s_T.shape[1])
        ends = np.cumsum([len(r) for r in rows])
        starts = ends - [len(r) for r in rows]
        _, a_S, _, references = first._references(s_T)
        nominal = first._nominal(len(s_T), a_S)
        responses = [policies[b]._responses(s_T[a:z], nominal[a:z]) for b, a, z in zip(blocks, starts, ends)]
        free = np.concatenate([f for f, _ in responses])
        control = np.concatenate([g for _, g in responses])
        adaptive, action = first._correction(references, nominal, free, control)
        return s_T, nominal + adaptive, action, [(int(a), int(z)) for a, z in zip(starts, ends)]

    return joint


def _closed_form(
    affine: tuple[np.ndarray, np.ndarray, np.ndarray], horizon: int, m: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A^j and sum_{i<j} A^i for j = 1..H (H, d, d), G_j = (sum_{i<j} A^i) B (H, d, m), c, B."""
    a, b, c = (np.asarray(x, dtype=np.float64) for x in affine)
    b = b[:, None] if b.ndim == 1 else b
    d = a.shape[0] if a.ndim == 2 else -1
    if a.shape != (d, d) or b.shape != (d, m) or c.shape != (d,) or not all(np.all(np.isfinite(x)) for x in (a, b, c)):
        raise ValueError(
            f"affine must be finite (A (d, d), B (d, {m}), c (d,)), got shapes {a.shape}, {b.shape}, {c.shape}"
        )
    powers, sums = np.empty((horizon, d, d)), np.empty((horizon, d, d))
    power, total = np.eye(d), np.zeros((d, d))
    for j in range(horizon):
        total = total + power
        power = a @ power
        powers[j], sums[j] = power, total
    return powers, sums, sums @ b, c, b


__all__ = ["REFERENCES", "HorizonStep", "HorizonTATLPolicy", "shared_decisions", "shared_premises"]
