"""The theorem's premises measured on a TA-TL method unit's own evaluation episodes.

``tatl_mj.transfer.premises`` holds the measures; this module feeds them what the
evaluation shows. A :class:`PremiseObserver` sits in ``evaluate_curve``'s lockstep:
it answers a TA-TL policy's decisions through the policy's ``premise_step`` hook
(the same decision as calling it, with the request before clipping and s_hat_next
beside it: ``tatl_mj.transfer.method.premise_probe``), and at the budgets chosen for
the finite-difference measures it keeps a seeded reservoir of :data:`VISITS` visited
states as replay visits (``tatl_mj.sampling.replay``). It only reads: returns,
lengths and every other record field are what an unobserved evaluation gives
(finite differences run on a scratch MjData of an environment of their own).

:func:`PremiseObserver.measurements` then gives each policy's
:class:`~tatl_mj.transfer.premises.PremiseMeasurements` as a record's ``premises``
object (docs/protocol.md, "The theorem's premises, measured").
"""

from __future__ import annotations

import copy
import dataclasses
import math
from typing import Any, Callable, Sequence

import mujoco
import numpy as np

from tatl_mj.description import TaskDescription
from tatl_mj.experiments.run.evaluation import per_episode
from tatl_mj.experiments.spec.schema import Side
from tatl_mj.sampling import replay
from tatl_mj.sampling.simulator import simulator_for
from tatl_mj.transfer import method, premises
from tatl_mj.transfer.apprentice import state_snap
from tatl_mj.transitions import Transitions

VISITS = 64
"""Visited states per finite-difference budget whose B(s), alpha and affinity are measured."""
FD_EPS = 1e-3
"""The central differences' step in actuator units."""


MEASURES = tuple(f.name for f in dataclasses.fields(premises.PremiseMeasurements))
"""Every measure a record's ``premises`` holds."""
FINITE_DIFFERENCES = ("alpha", "unexplained", "b_spread")
"""The measures taken on the kept visits (:data:`VISITS` per finite-difference budget)."""


def measures_of(policy: Any) -> frozenset[str]:
    """The measures a policy's premises get: its ``premise_measures`` (names of
    :class:`~tatl_mj.transfer.premises.PremiseMeasurements`' fields; the method contract),
    else every one. The rest are null in its records; a declared one is null where its
    step or target does not give what it is measured by (e.g. tracking without s_hat_next)."""
    declared = getattr(policy, "premise_measures", None)
    if declared is None:
        return frozenset(MEASURES)
    unknown = sorted(set(declared) - set(MEASURES))
    if unknown:
        raise ValueError(f"{type(policy).__name__}.premise_measures names {unknown}: each must be one of {MEASURES}")
    return frozenset(declared)


def fd_budgets(budgets: Sequence[int]) -> tuple[int, ...]:
    """The budgets whose policies get the finite-difference measures: smallest, middle, largest."""
    n = len(budgets)
    return tuple(sorted({int(budgets[0]), int(budgets[n // 2]), int(budgets[-1])}))


@dataclasses.dataclass
class _Block:
    """What one observed policy's episodes showed, call by call."""

    probe: Callable[[np.ndarray], Any]
    measures: frozenset[str]
    calls: list[tuple[np.ndarray, np.ndarray]] = dataclasses.field(default_factory=list)
    # per call: the requests before clipping, and [projected | predicted] next states
    asked: list[tuple[np.ndarray, np.ndarray]] = dataclasses.field(default_factory=list)
    visits: list[tuple[replay.Visit, np.ndarray]] = dataclasses.field(default_factory=list)
    seen: int = 0  # visited states offered to the reservoir so far


class PremiseObserver:
    """Observes a curve's lockstep evaluation for the premises of its TA-TL policies.

    ``policies`` are the distinct policies evaluated together (blocks in that order);
    ``visit_blocks`` those whose visited states are kept for the finite-difference
    measures (only those of policies that declare one); ``seed`` seeds the reservoir of
    visits (one choice per unit). Where the policies decide together (``decide_together``)
    and answer the premises together too (``premise_together``), the observed blocks are
    answered by that joint computation, so the decisions stay the joint path's.
    """

    def __init__(self, policies: Sequence[Any], visit_blocks: Sequence[int], n_episodes: int, seed: int):
        self.policies = list(policies)
        self.n_episodes = n_episodes
        self.blocks: dict[int, _Block] = {}
        for b, policy in enumerate(self.policies):
            probe = method.premise_probe(policy)
            if probe is not None:
                self.blocks[b] = _Block(probe, measures_of(policy))
        self.together = method.joint_premises(self.policies) if self.blocks else None
        self.visit_blocks = {
            b for b in visit_blocks if b in self.blocks and self.blocks[b].measures & set(FINITE_DIFFERENCES)
        }
        self.random = np.random.default_rng(seed)

    @property
    def active(self) -> bool:
        return bool(self.blocks)

    def joint(self, together: method.JointDecisions) -> method.JointDecisions:
        """``together`` with the observed blocks answered by their ``premise_step`` (the same values)."""

        def decide(blocks: list[int], states: list[np.ndarray]) -> list[np.ndarray]:
            rest = [(k, b) for k, b in enumerate(blocks) if b not in self.blocks]
            values: list[Any] = [None] * len(blocks)
            if rest:
                answers = together([b for _, b in rest], [states[k] for k, _ in rest])
                for (k, _), v in zip(rest, answers):
                    values[k] = v
            mine = [(k, b) for k, b in enumerate(blocks) if b in self.blocks]
            if not mine:
                return values
            if self.together is not None:  # the joint path's own computation, with its steps
                steps = self.together([b for _, b in mine], [states[k] for k, _ in mine])
            else:
                steps = [self.blocks[b].probe(states[k]) for k, b in mine]
            for (k, b), step in zip(mine, steps):
                block = self.blocks[b]
                values[k] = step.action
                s = np.array(states[k], dtype=np.float64)
                block.calls.append((s, np.atleast_2d(np.array(step.action, dtype=np.float64).T).T))
                nan = np.full_like(block.calls[-1][1], np.nan)
                requested = nan if step.requested is None else np.array(step.requested, dtype=np.float64)
                projected = np.full_like(s, np.nan) if step.projected is None else np.array(step.projected)
                predicted = np.full_like(s, np.nan) if step.predicted is None else np.array(step.predicted)
                block.asked.append((requested, np.concatenate([projected, predicted], axis=1)))
            return values

        return decide

    def visitor(
        self,
        step: int,
        live: np.ndarray,
        values: np.ndarray,
        rows: Callable[[np.ndarray], np.ndarray],
        random_of: Callable[[int], Any],
    ) -> None:
        """The sampling.Visitor: a seeded reservoir of each visit block's (state, action) pairs."""
        for b in self.visit_blocks:
            block = self.blocks[b]
            mine = np.flatnonzero(live // self.n_episodes == b)
            if not len(mine):
                continue
            counts = block.seen + 1 + np.arange(len(mine))
            block.seen += len(mine)
            slots = np.where(counts <= VISITS, counts - 1, np.floor(self.random.random(len(mine)) * counts))
            keep = np.flatnonzero(slots < VISITS)
            if not len(keep):
                continue
            states = rows(live[mine[keep]])
            for j, k in enumerate(keep):
                sim_id = int(live[mine[k]])
                visit = replay.Visit(states[j], int(step), _copied(random_of(sim_id)))
                pair = (visit, np.array(values[mine[k]], dtype=np.float64).ravel())
                slot = int(slots[k])
                if slot < len(block.visits):
                    block.visits[slot] = pair
                else:
                    block.visits.append(pair)

    def measurements(
        self,
        lengths: Sequence[np.ndarray],
        target: TaskDescription,
        stream: Transitions,
        samples_used: Sequence[int],
        side: Side,
    ) -> list[dict | None]:
        """Per block: its premises as a record's JSON object, None where not TA-TL's.

        ``lengths`` per block its episodes' lengths; ``samples_used`` per block the
        stream head its apprentice was fitted on (``delta_stream``); ``side`` the spec's
        target (its domain, as the spec names it, a user's ``module:attribute`` too, task and
        task_kwargs), for the environment the visits are replayed in."""
        out: list[dict | None] = []
        for b, policy in enumerate(self.policies):
            block = self.blocks.get(b)
            if block is None:
                out.append(None)
                continue
            found = _measure(policy, block, np.asarray(lengths[b]), target, stream, int(samples_used[b]), side)
            out.append({k: _number(v) for k, v in dataclasses.asdict(found).items()})
        return out


def _copied(random: Any) -> Any:
    """A copy of the stream as it stands before the step (visit_of's rule: later draws must not move it)."""
    return None if random is None else copy.deepcopy(random)


DIVERGED = 1e300
"""A record's value for a NaN or infinite measure (a diverged prediction or step): JSON has
no NaN, and this fails every threshold, as nothing shows the premise holds."""


def _number(value: float | None) -> float | None:
    """A JSON number or null (not measured); NaN and inf as :data:`DIVERGED`."""
    if value is None:
        return None
    return float(value) if math.isfinite(value) else DIVERGED


def _episodes(calls: list[tuple[np.ndarray, np.ndarray]], lengths: np.ndarray) -> list[np.ndarray]:
    a, b = per_episode(calls, lengths)
    return [np.concatenate([x, y], axis=1) for x, y in zip(a, b)]


def _measure(
    policy: Any,
    block: _Block,
    lengths: np.ndarray,
    target: TaskDescription,
    stream: Transitions,
    used: int,
    side: Side,
) -> premises.PremiseMeasurements:
    """One policy's measurements from its observed episodes and kept visits: those it
    declares (:func:`measures_of`) and its step and target give."""
    if not block.calls:  # nothing decided through the observer: nothing to measure
        return premises.PremiseMeasurements()
    wanted = block.measures
    apprentice, mapping = getattr(policy, "apprentice", None), policy.mapping
    periodic = target.periodic if any(target.periodic) else None
    d = target.state_dim
    decided = _episodes(block.calls, lengths)  # per episode: [states | values]
    asked = _episodes(block.asked, lengths)  # per episode: [requested | projected | predicted]
    m = decided[0].shape[1] - d
    # Decision t's next state is decision t + 1's state: an episode's last decision has none seen.
    s = np.concatenate([e[:-1, :d] for e in decided])
    a = np.concatenate([e[:-1, d:] for e in decided])
    s_next = np.concatenate([e[1:, :d] for e in decided])
    visited = np.concatenate([e[:, :d] for e in decided])
    requested = np.concatenate([e[:, :m] for e in asked])
    applied = np.concatenate([e[:, d:] for e in decided])
    projected = np.concatenate([e[:-1, m : m + d] for e in asked])
    predicted = np.concatenate([e[:-1, m + d :] for e in asked])
    given = bool(len(s)) and not np.all(np.isnan(predicted))  # the policy's own predictions
    found: dict[str, float | None] = {}
    if "infeasible" in wanted and not np.all(np.isnan(requested)):
        if target.discrete:  # an index request: available where it is one of the target's actions
            low, high = np.zeros(1), np.full(1, target.n_actions - 1.0)
        else:
            low, high = target.action_low, target.action_high
        found["infeasible"] = premises.feasibility(requested, applied, low, high).infeasible
    if target.discrete and len(s) and "misprediction" in wanted:
        if given:
            found["misprediction"] = premises.mispredicted(predicted, s_next)
        elif apprentice is not None:
            values = target.action_values[a[:, 0].astype(np.int64)]
            found["misprediction"] = premises.misprediction_rate(apprentice, s, values, s_next, state_snap(target))
    if not wanted - {"infeasible", "misprediction"}:
        return premises.PremiseMeasurements(**found)
    try:
        scale = premises.step_scale(stream.states, stream.next_states, periodic)
    except ValueError:  # a coordinate the stream never moves: nothing to scale by
        return premises.PremiseMeasurements(**_only(found, wanted))
    if "round_trip" in wanted:
        found["round_trip"] = premises.round_trip(mapping, visited, scale, periodic).rms
    if target.discrete:
        return premises.PremiseMeasurements(**_only(found, wanted))
    if apprentice is not None and "delta_stream" in wanted:
        head = stream.head(max(used, 1))
        found["delta_stream"] = premises.one_step_errors(
            apprentice, head.states, target.action_values[head.actions], head.next_states, scale, periodic
        ).rms
    if len(s):
        if given:
            found["delta"] = premises.normalised_errors(predicted, s_next, scale, periodic).rms
        elif apprentice is not None:
            found["delta"] = premises.one_step_errors(apprentice, s, a, s_next, scale, periodic).rms
        if not np.all(np.isnan(projected)):
            found["tracking"] = premises.tracking(s_next, projected, scale, periodic).rms
    if block.visits and apprentice is not None:
        found.update(_finite_differences(apprentice, block.visits, target, side, scale, periodic))
    return premises.PremiseMeasurements(**_only(found, wanted))


def _only(found: dict[str, float | None], wanted: frozenset[str]) -> dict[str, float | None]:
    """The measures ``wanted`` of those ``found``: the rest stay null."""
    return {k: v for k, v in found.items() if k in wanted}


def _finite_differences(
    apprentice: Any,
    visits: list[tuple[replay.Visit, np.ndarray]],
    target: TaskDescription,
    side: Side,
    scale: np.ndarray,
    periodic: Sequence[bool] | None,
) -> dict[str, float]:
    """alpha, control affinity and B(s)'s spread over the kept visits, each replayed in a
    scratch MjData of an environment of its own (the evaluation's are left alone)."""
    env = simulator_for(side.domain, side.task, side.task_kwargs, 1).make_env(0)
    env.reset()
    data = mujoco.MjData(env.physics.model.ptr)
    low, high = target.action_low, target.action_high
    Bs, unexplained = [], []
    for visit, action in visits:
        step = replay.control_step(env, visit, data)
        Bs.append(premises.finite_difference_B(step, action, FD_EPS, periodic, low, high))
        unexplained.append(premises.control_affinity(step, low, high, scale=scale, periodic=periodic).unexplained)
    B = np.stack(Bs)
    if not np.all(np.isfinite(B)):
        return {"alpha": math.nan, "unexplained": float(np.mean(unexplained)), "b_spread": math.nan}
    return {
        "alpha": premises.alpha(apprentice.B, B).mean_error,
        "unexplained": float(np.mean(unexplained)),
        "b_spread": premises.b_spread(B, scale),
    }


__all__ = [
    "DIVERGED",
    "FD_EPS",
    "FINITE_DIFFERENCES",
    "MEASURES",
    "VISITS",
    "PremiseObserver",
    "fd_budgets",
    "measures_of",
]
