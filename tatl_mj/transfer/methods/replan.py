"""``ta-tl-replan`` and ``ta-tl-oracle``: TA-TL on a discrete target, by planning and by the one-step rule.

:class:`ReplanTATL` departs from Algorithm 1 on purpose: it plans (exact
Q-iteration, :func:`replan`) on the source's known model carried through the
mapping, corrected by a tabular apprentice of the target wherever target data
exist (``tatl_mj.transfer.tabular``, whose docstring says why).
:class:`OneStepOracle` is Algorithm 1's one-step rule with the exact target model
as its apprentice (:class:`OneStepRule`), an ablation that shows how much of a
failure is the rule's and how much the apprentice's.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from tatl_mj.description import CellMap, TaskDescription
from tatl_mj.transfer.algorithm1 import PremiseStep, SourceStep
from tatl_mj.transfer.features import as_states
from tatl_mj.transfer.fqi import QFunction
from tatl_mj.transfer.intertask_mapping import Mapping
from tatl_mj.transfer.method import TransferProblem
from tatl_mj.transfer.tabular import (
    PRIOR_SCOPES,
    TabularApprentice,
    TabularModel,
    fit_tabular_apprentice,
    mapped_model,
    uninformed_model,
)
from tatl_mj.transfer.tabular_q import TabularQ
from tatl_mj.transitions import Transitions
from tatl_mj.validation import Boolean, Constraints, Interval, Options, check_settings


@dataclasses.dataclass(frozen=True)
class ReplanStep:
    """One batched decision of :class:`ReplanPolicy`."""

    cell: np.ndarray  # (N,) cell index of each target state
    values: np.ndarray  # (N, A) Q of the merged model
    action: np.ndarray  # (N,) greedy action (lowest index on ties)
    from_target: np.ndarray  # (N,) whether the chosen pair's model came from target data


@dataclasses.dataclass(frozen=True, eq=False)
class ReplanPolicy:
    """The greedy policy of Q-iteration on the merged model, over target states.

    Also a ``QFunction`` (``values``, ``greedy``, ``n_actions``) over target states.

    Attributes:
      q: Q over cell indices.
      cell_map: target states -> cells.
      model: the merged model that was planned on.
      visited: (S, A) pairs whose model came from target data.
      samples_used: target samples the apprentice counted, for reports.
      mapping: chi / chi_plus where the policy read the source (its premises' round
        trip); None for the source-free ablation (no premises measured).
    """

    q: TabularQ
    cell_map: CellMap
    model: TabularModel
    visited: np.ndarray
    samples_used: int | None = None
    mapping: Mapping | None = None

    premise_measures: ClassVar[tuple[str, ...]] = ("misprediction", "infeasible", "round_trip")
    """The premises measured for it (``run.premises.measures_of``): the merged model's
    misprediction (the grid's delta), feasibility and the mapping's round trip. Its
    request is an index of the target's own action set, so every request is available
    and infeasible is 0 by construction: measured, so that a record shows it."""

    @property
    def n_actions(self) -> int:
        return self.q.n_actions

    def step(self, target_states: np.ndarray) -> ReplanStep:
        cell = self.cell_map.index(target_states)
        values = self.q.q[cell]
        action = np.argmax(values, axis=1).astype(np.int64)
        return ReplanStep(cell, values, action, self.visited[cell, action])

    def values(self, states: np.ndarray) -> np.ndarray:
        return self.q.q[self.cell_map.index(states)]

    def greedy(self, states: np.ndarray) -> np.ndarray:
        return self.step(states).action

    def __call__(self, target_states: np.ndarray) -> np.ndarray:
        """(N, d) target states -> (N,) int64 action indices."""
        return self.step(target_states).action

    def premise_step(self, target_states: np.ndarray) -> PremiseStep:
        """The method contract's ``premise_step`` hook: ``__call__``'s indices (one
        :meth:`step`), the requested index (the greedy one: the planner asks only for
        actions the target has) and the merged model's next cell for it."""
        step = self.step(target_states)
        predicted = self.cell_map.cells[self.model.next_state[step.cell, step.action]].astype(np.float64)
        return PremiseStep(step.action, step.action.astype(np.float64)[:, None], None, predicted)


def replan(
    apprentice: TabularApprentice,
    cell_map: CellMap,
    gamma: float,
    samples_used: int | None = None,
    tol: float = 1e-10,
    mapping: Mapping | None = None,
) -> ReplanPolicy:
    """``ta-tl-replan``: exact Q-iteration on the apprentice's model with its fallback."""
    if cell_map.n_cells != apprentice.n_cells:
        raise ValueError(f"cell_map has {cell_map.n_cells} cells, the apprentice {apprentice.n_cells}")
    model = apprentice.model()
    return ReplanPolicy(model.q(gamma, tol), cell_map, model, apprentice.visited, samples_used, mapping)


# --- The one-step rule with a tabular model (the oracle ablation) ----------------------


@dataclasses.dataclass(frozen=True)
class OneStepDecision:
    """Every quantity of one Algorithm 1 decision with a tabular target model (batched)."""

    s_hat_S: np.ndarray  # (N, dS) chi_plus(s_T)
    a_S: np.ndarray  # (N,) greedy source action
    s_S_next: np.ndarray  # (N, dS) the source simulator's next state
    s_hat_T_next: np.ndarray  # (N, dT) chi(s_S_next)
    predicted: np.ndarray  # (N, A, dT) the model's next state for every target action
    distances: np.ndarray  # (N, A) |predicted - s_hat_T_next|
    action: np.ndarray  # (N,) nearest; ties go to a_S, else the lowest index


@dataclasses.dataclass(frozen=True, eq=False)
class OneStepRule:
    """Algorithm 1's rule with a tabular model of the target as its apprentice.

    Picks the target action whose next cell under ``model`` lands nearest the
    projected source next state ``chi(P_S(chi_plus(s_T), a_S))``, as
    ``tatl.DiscreteTATLPolicy`` does with a control-affine apprentice. With the
    exact target model (``TabularModel(*description[:3])``) it is the oracle
    ablation: what the one-step rule scores when the apprentice is perfect.
    """

    source_q: QFunction
    mapping: Mapping
    source_step: SourceStep
    model: TabularModel
    cell_map: CellMap

    def __post_init__(self) -> None:
        if self.model.n_cells != self.cell_map.n_cells:
            raise ValueError(f"model has {self.model.n_cells} cells, cell_map has {self.cell_map.n_cells}")
        if self.source_q.n_actions != self.model.n_actions:
            raise ValueError(f"source_q has {self.source_q.n_actions} actions, model has {self.model.n_actions}")

    def step(self, target_states: np.ndarray) -> OneStepDecision:
        s_T = as_states(target_states, "target_states", self.cell_map.state_dim)
        cell = self.cell_map.index(s_T)
        s_hat_S = self.mapping.chi_plus(s_T)
        a_S = np.asarray(self.source_q.greedy(s_hat_S), dtype=np.int64)
        s_S_next = np.asarray(self.source_step(s_hat_S, a_S), dtype=np.float64)
        s_hat_T_next = self.mapping.chi(s_S_next)
        predicted = self.cell_map.cells[self.model.next_state[cell]].astype(np.float64)
        distances = np.linalg.norm(predicted - s_hat_T_next[:, None, :], axis=2)
        near = distances <= distances.min(axis=1, keepdims=True) + 1e-9
        rows = np.arange(len(cell))
        action = np.where(near[rows, a_S], a_S, np.argmax(near, axis=1)).astype(np.int64)
        return OneStepDecision(s_hat_S, a_S, s_S_next, s_hat_T_next, predicted, distances, action)

    def __call__(self, target_states: np.ndarray) -> np.ndarray:
        """(N, dT) target states -> (N,) int64 target action indices."""
        return self.step(target_states).action


# --- Methods -------------------------------------------------------------------------


def _target_cells(problem: TransferProblem) -> np.ndarray:
    """The target's cells (its state set): from its description's known model where it has
    one (only the list of cells is read), else the source's, mapped through chi."""
    if problem.target.known_model is not None:
        return problem.target.known_model()[3]
    return np.rint(problem.mapping.chi(problem.source.known_model()[3].astype(np.float64))).astype(np.int64)


@dataclasses.dataclass(frozen=True)
class ReplanTATL:
    """``ta-tl-replan``: plan on the source MDP corrected by a tabular apprentice of the target.

    Departs from Algorithm 1: the one-step rule, even with the exact target model,
    scores about 2.4 of 10 on the windy grid (four unit moves cannot cancel the
    wind, and tracking the projected next state loops), so instead of matching the
    source's next state this replans: Q-iteration on the source's known model,
    carried through the mapping, whose transitions are replaced by the apprentice's
    wherever target data exist (``TabularApprentice``).

    Settings: ``gamma`` of the planner; ``source_prior`` (False: the
    ``replan-no-source`` ablation, unvisited pairs stay put with reward 0, so only
    the apprentice plans); ``prior_scope`` (``PRIOR_SCOPES``); ``data``: ``"shared"``
    (the shared random-policy samples, as every method) or ``"source-policy"`` (the
    paper's protocol: the budget is spent running the projected source policy from
    the target's random starts).
    """

    gamma: float = 0.95
    source_prior: bool = True
    prior_scope: str = "agreeing-cells"
    data: str = "shared"
    name: str = "ta-tl-replan"

    constraints: ClassVar[Constraints] = {
        "gamma": [Interval(float, 0, 1, closed="left")],
        "source_prior": [Boolean()],
        "prior_scope": [Options(*PRIOR_SCOPES)],
        "data": [Options("shared", "source-policy")],
    }

    def __post_init__(self) -> None:
        check_settings(self)

    @property
    def uses_source(self) -> bool:
        """False for ``replan-no-source`` on the shared stream: it plans on the apprentice alone."""
        return self.source_prior or self.data == "source-policy"

    @property
    def ablation_of(self) -> tuple[str, ...]:
        """Without the source: the ablation of the planners on the tabular apprentice, and of
        ``ta-tl`` on a target whose states are cells (the grid)."""
        return () if self.uses_source else ("ta-tl", "ta-tl-replan", "ta-tl-replan-protocol")

    def check(self, source: TaskDescription, target: TaskDescription) -> None:
        owner = type(self).__name__
        if not target.discrete:
            raise ValueError(f"{owner} plans over cells: the target must take action indices")
        if source.known_model is None:
            raise ValueError(f"{owner} plans on the source's known model; {source.domain}/{source.task} has none")
        if not self.uses_source and target.known_model is None:
            # Its cells would come from the source's, through the mapping, which it does not read.
            raise ValueError(
                f"{owner}(source_prior=False) reads no source: it needs the target's cells (a known model); "
                f"{target.domain}/{target.task} has none"
            )

    def learn(self, problem: TransferProblem, target_samples: Transitions) -> ReplanPolicy:
        self.check(problem.source, problem.target)
        cells = CellMap(_target_cells(problem))
        n_actions = problem.target.n_actions
        if self.source_prior:
            next_state, reward, absorbing, source_cells = problem.source.known_model()
            fallback = mapped_model(
                TabularModel(next_state, reward, absorbing), CellMap(source_cells), cells, problem.mapping
            )
        else:
            fallback = uninformed_model(cells.n_cells, n_actions)
        samples = target_samples
        if self.data == "source-policy":
            if problem.policy_samples is None:
                raise ValueError(f"{type(self).__name__}(data='source-policy') needs the problem's policy_samples")
            samples = problem.policy_samples(problem.projected_source_policy(), len(target_samples))
        apprentice = fit_tabular_apprentice(samples, cells, fallback, self.prior_scope)
        # The mapping rides along only where the method reads the source (the premises' round
        # trip): the source-free ablation's problem withholds it.
        mapping = problem.mapping if self.uses_source else None
        return replan(apprentice, cells, self.gamma, samples_used=len(samples), mapping=mapping)


@dataclasses.dataclass(frozen=True)
class OneStepOracle:
    """``ta-tl-oracle``: Algorithm 1's one-step rule with the exact target model as its apprentice.

    An ablation (it reads the target's known model, no samples): what the paper's
    rule scores when the apprentice is perfect, so the reader sees how much of a
    failure is the rule's and how much the apprentice's.
    """

    name: str = "ta-tl-oracle"
    uses_samples = False
    privileges = ("true model",)  # it reads the target's true model, which a robot has no access to
    constraints: ClassVar[Constraints] = {}  # no settings

    def check(self, source: TaskDescription, target: TaskDescription) -> None:
        if target.known_model is None:
            raise ValueError(
                f"{type(self).__name__} needs the target's known model; {target.domain}/{target.task} has none"
            )

    def learn(self, problem: TransferProblem, target_samples: Transitions) -> OneStepRule:
        self.check(problem.source, problem.target)
        next_state, reward, absorbing, cells = problem.target.known_model()
        return OneStepRule(
            problem.source_q,
            problem.mapping,
            problem.source_step,
            TabularModel(next_state, reward, absorbing),
            CellMap(cells),
        )


__all__ = [
    "OneStepDecision",
    "OneStepOracle",
    "OneStepRule",
    "ReplanPolicy",
    "ReplanStep",
    "ReplanTATL",
    "replan",
]
