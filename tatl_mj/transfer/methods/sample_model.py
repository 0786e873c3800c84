"""``apprentice-fqi-samples``: model-based RL on what the counted samples give, no source, no privilege.

The source-free comparator of ``ta-tl`` that a robot could run: it fits ``ta-tl``'s
apprentice ``s' = W phi(s) + B a`` on every one of the counted target samples (as
``ta-tl-no-alg2`` does), learns the reward and end condition from the rewards and
ends those samples observed (``tatl_mj.transfer.reward_model``), and solves the
target by FQI on the samples themselves and on transitions its two models predict,
for every action, from

- the samples' own states, and
- the states the apprentice visits in ``rounds`` rounds of "roll the current
  epsilon-greedy policy out in the apprentice for ``horizon`` steps from ``starts``
  sample states, add what it visits, refit FQI": a random-policy stream never leaves
  the bottom of a pendulum, so one-step transitions from its states alone could never
  teach balancing; the rounds let the model explore, as TA-TL's source lets it.
  With ``round_iterations`` each refit starts from the previous round's Q (warm):
  the fits that only steer the next rollouts take that many iterations, the last
  one, which becomes the policy, all of ``iterations``.

It never calls the target task's reward function, resets the target or draws from its
reset box, steps its simulator, or asks any other hook of the problem for transitions:
everything it learns from is in the samples it is given. A discrete target's
predicted states are put on the nearest cell the samples visited. Its policy reports
the reward model's error on samples held out from its fit (``reward_errors``).
Compared with ``apprentice-fqi`` (TA-TL's ablation that scores the apprentice's
transitions from the reset box with the task's own reward: privileged), a TA-TL win
over this one is a win a robot's model-based learner could not match with the same data.
"""

from __future__ import annotations

import dataclasses
from typing import Callable, ClassVar

import numpy as np

from tatl_mj.description import CellMap, TaskDescription
from tatl_mj.transfer.apprentice import Apprentice
from tatl_mj.transfer.features import FeaturesSpec, check_features
from tatl_mj.transfer.fqi import QFunction, fitted_q_iteration, make_regressor
from tatl_mj.transfer.method import Policy, TransferProblem
from tatl_mj.transfer.methods.target_fqi import GreedyPolicy, TargetFQI
from tatl_mj.transfer.methods.tatl import TATL
from tatl_mj.transfer.reward_model import (
    REWARD_INPUTS,
    HeldOutErrors,
    RewardModel,
    fit_reward_model,
    held_out_errors,
    reward_bases,
)
from tatl_mj.transitions import Transitions
from tatl_mj.validation import Constraints, Interval, InvalidSetting, ListOf, Options

TRUST = 1.0
"""A rollout ends where the apprentice leaves the samples' range widened by this many of its
widths on each side (angles excepted): a wild fit's blow-up is not exploration."""


@dataclasses.dataclass(frozen=True, eq=False)
class SampleModelPolicy(GreedyPolicy):
    """The greedy policy of ``apprentice-fqi-samples``, with what its learning reports.

    Attributes (besides :class:`GreedyPolicy`'s):
      reward_errors: the reward and end model's errors on held-out samples.
      model_states: how many states the model's transitions were predicted from
        (the samples' own and the rollouts'), before the ``model_samples`` cap.
    """

    reward_errors: HeldOutErrors = HeldOutErrors(samples=0)
    model_states: int = 0

    @property
    def reward_error(self) -> float | None:
        """The reward model's root mean square error on the held-out samples (None: none held out)."""
        return self.reward_errors.reward_rmse

    @property
    def end_error(self) -> float | None:
        """The fraction of held-out samples whose end the model mispredicts (None: none held out)."""
        return self.reward_errors.end_error


@dataclasses.dataclass(frozen=True)
class ApprenticeFQISamples(TargetFQI):
    """FQI on the samples and on the apprentice's and the learned reward's transitions.

    Attributes (besides :class:`TargetFQI`'s learner settings, which a spec sets to the
    RL baseline's; ``data`` is the shared stream only, ``epsilon`` the rollouts' rate of
    uniformly random actions, ``online_batch`` unused):
      apprentice: the apprentice's basis phi, as ``ta-tl``'s (a features spec).
      apprentice_ridge: its least squares' ridge, as ``ta-tl``'s ``ridge``.
      rounds: how many times the current policy is rolled out in the apprentice and
        FQI refitted with the states it visited (0: the samples' states only).
      horizon: each rollout's steps (it ends earlier where the learned end condition
        holds or the apprentice leaves the samples' range, see :data:`TRUST`).
      starts: how many sample states each round's rollouts start from, drawn anew each
        round, or ``"all"``.
      round_iterations: None, every fit from Q_0 = 0 with ``iterations``; or the FQI
        iterations of the rounds' intermediate refits, each started from the previous
        round's Q, the last refit (the policy's) then also started there but with every
        one of ``iterations``. An intermediate fit only steers the next rollouts, and a
        warm start carries the iterations already done, so fewer suffice (the fits are
        most of the method's cost).
      reward_features: the reward and end model's basis: a features spec, or a list of
        them side by side (None: the FQI learner's features).
      reward_inputs: ``"next"``, a reward of the state reached, or ``"transition"``, of
        the step (see ``tatl_mj.transfer.reward_model``).
      reward_ridge: the reward and end model's ridge.
      holdout: the fraction of the samples held out to measure the reward model's error
        (the model used is then fitted on every sample).
      model_samples: the most model transitions one FQI fit learns from (states times
        actions; the states drawn at random where there are more), as ``apprentice-fqi``'s.
    """

    apprentice: dict = dataclasses.field(default_factory=lambda: {"kind": "linear"})
    apprentice_ridge: float = 0.0
    rounds: int = 4
    horizon: int = 100
    starts: int | str = 100
    round_iterations: int | None = None
    reward_features: dict | tuple[dict, ...] | None = None
    reward_inputs: str = "next"
    reward_ridge: float = 1e-6
    holdout: float = 0.2
    model_samples: int = 20000
    name: str = "apprentice-fqi-samples"
    ablation_of = ("ta-tl",)  # ta-tl's own apprentice without the source, as ta-tl-no-alg2 fits it
    privileges = ()  # only the counted samples, its apprentice and its computation

    constraints: ClassVar[Constraints] = {
        **TargetFQI.constraints,
        "data": [Options("shared")],
        "apprentice": [FeaturesSpec()],
        "apprentice_ridge": [Interval(float, 0)],
        "rounds": [Interval(int, 0)],
        "horizon": [Interval(int, 1)],
        "starts": [Options("all"), Interval(int, 1)],
        "round_iterations": [None, Interval(int, 1)],
        "reward_features": [None, FeaturesSpec(), ListOf(FeaturesSpec(), nonempty=True)],
        "reward_inputs": [Options(*REWARD_INPUTS)],
        "reward_ridge": [Interval(float, 0)],
        "holdout": [Interval(float, 0, 1, closed="left")],
        "model_samples": [Interval(int, 1)],
    }

    @property
    def reward_basis(self) -> dict | tuple[dict, ...]:
        return self.linear_features if self.reward_features is None else self.reward_features

    def check(self, source: TaskDescription, target: TaskDescription) -> None:
        super().check(source, target)
        owner = type(self).__name__
        check_features(owner, "apprentice", self.apprentice, target.state_dim)
        basis = self.reward_basis
        for spec in basis if isinstance(basis, tuple) else (basis,):
            check_features(owner, "reward_features", spec, target.state_dim)
        if self.model_samples < target.n_actions:
            raise InvalidSetting(
                f"{owner}.model_samples ({self.model_samples}) must cover one state's {target.n_actions} actions"
            )

    def fit_apprentice(self, problem: TransferProblem, data: Transitions) -> Apprentice:
        """``ta-tl``'s apprentice fitted on every sample of ``data`` (as ``ta-tl-no-alg2``'s)."""
        tatl = TATL(apprentice=self.apprentice, ridge=self.apprentice_ridge, zeta=None)
        return tatl.fit_apprentice(problem, data)[0]

    def learn(self, problem: TransferProblem, target_samples: Transitions) -> Policy:
        rng = np.random.default_rng(problem.seed)
        target = problem.target
        apprentice = self.fit_apprentice(problem, target_samples)
        bases = reward_bases(self.reward_basis, target.state_dim)
        fit = (bases, self.reward_inputs, target.n_actions, self.reward_ridge)
        errors = held_out_errors(target_samples, *fit, holdout=self.holdout, rng=rng)
        rewards = fit_reward_model(target_samples, *fit)
        q, states = self.plan(problem, target_samples, apprentice, rewards, rng)
        return SampleModelPolicy(
            q,
            target.action_values,
            target.discrete,
            samples_used=len(target_samples),
            reward_errors=errors,
            model_states=len(states),
        )

    def plan(
        self,
        problem: TransferProblem,
        data: Transitions,
        apprentice: Apprentice,
        rewards: RewardModel,
        rng: np.random.Generator,
    ) -> tuple[QFunction, np.ndarray]:
        """FQI on the samples and the models' transitions from their states, then ``rounds`` of
        rollouts that add states; returns the last Q and every state the models started from."""
        target = problem.target
        model = _Model(apprentice, rewards, target.action_values, _cell_snap(data) if target.discrete else None)
        states = np.unique(np.vstack([data.states, data.next_states]), axis=0)
        q = self.fqi(problem, Transitions.concatenate([data, self.model_transitions(model, states, rng)]), rng)
        inside = _trust_region(data, target.periodic)
        for round_ in range(self.rounds):
            visited = model.rollouts(q, self._starts(data, rng), self.horizon, self.epsilon, inside, rng)
            states = np.vstack([states, visited])
            both = Transitions.concatenate([data, self.model_transitions(model, states, rng)])
            if self.round_iterations is None:
                q = self.fqi(problem, both, rng)
            else:
                last = round_ == self.rounds - 1
                q = self.refit(both, q, self.iterations if last else self.round_iterations, rng)
        return q, states

    def refit(self, data: Transitions, start: QFunction, iterations: int, rng: np.random.Generator) -> QFunction:
        """FQI on ``data`` from Q_0 = ``start`` (a warm start), ``iterations`` of them."""
        regressor = make_regressor(self.regressor_spec(), data.state_dim)
        return fitted_q_iteration(data, start.n_actions, regressor, self.gamma, iterations, initial_q=start, rng=rng)

    def _starts(self, data: Transitions, rng: np.random.Generator) -> np.ndarray:
        if self.starts == "all" or int(self.starts) >= len(data):
            return data.states
        return data.states[rng.choice(len(data), size=int(self.starts), replace=False)]

    def model_transitions(self, model: "_Model", states: np.ndarray, rng: np.random.Generator) -> Transitions:
        """Every action's predicted transition from ``states`` (at most ``model_samples`` of them)."""
        n_actions = len(model.action_values)
        room = self.model_samples // n_actions
        if len(states) > room:
            states = states[np.sort(rng.choice(len(states), size=room, replace=False))]
        return model.transitions(np.repeat(states, n_actions, axis=0), np.tile(np.arange(n_actions), len(states)))


@dataclasses.dataclass(frozen=True, eq=False)
class _Model:
    """The learned target: the apprentice's next states (on a visited cell where the target is
    discrete) scored by the learned reward and end condition."""

    apprentice: Apprentice
    rewards: RewardModel
    action_values: np.ndarray
    snap: Callable[[np.ndarray], np.ndarray] | None

    def step(self, states: np.ndarray, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Next states (non-finite where the fit overflowed) and whether each is finite."""
        with np.errstate(all="ignore"):
            after = self.apprentice.predict(states, self.action_values[actions])
        finite = np.all(np.isfinite(after), axis=1)
        if self.snap is not None and finite.any():
            after[finite] = self.snap(after[finite])
        return after, finite

    def transitions(self, states: np.ndarray, actions: np.ndarray) -> Transitions:
        after, finite = self.step(states, actions)
        states, actions, after = states[finite], actions[finite], after[finite]
        rewards, ends = self.rewards.predict(states, actions, after)
        keep = np.isfinite(rewards)
        return Transitions(
            states=states[keep],
            actions=actions[keep],
            rewards=rewards[keep],
            next_states=after[keep],
            absorbing=ends[keep],
            last=np.ones(int(keep.sum()), dtype=bool),
        )

    def rollouts(
        self,
        q: QFunction,
        starts: np.ndarray,
        horizon: int,
        epsilon: float,
        inside: Callable[[np.ndarray], np.ndarray],
        rng: np.random.Generator,
    ) -> np.ndarray:
        """The states epsilon-greedy rollouts of ``q`` in the model visit from ``starts``, each
        until ``horizon`` steps, the learned end, or a state outside ``inside``."""
        states, visited = np.asarray(starts, np.float64), []
        for _ in range(horizon):
            if not len(states):
                break
            explore = rng.random(len(states)) < epsilon
            actions = np.where(explore, rng.integers(len(self.action_values), size=len(states)), q.greedy(states))
            after, finite = self.step(states, actions)
            kept = finite.copy()
            kept[finite] = inside(after[finite])
            states, actions, after = states[kept], actions[kept], after[kept]
            if not len(after):
                break
            visited.append(after)
            ends = self.rewards.predict(states, actions, after)[1]
            states = after[~ends]
        return np.vstack(visited) if visited else np.empty((0, self.apprentice.state_dim))


def _cell_snap(data: Transitions) -> Callable[[np.ndarray], np.ndarray]:
    """States put on the nearest cell the samples visited (a discrete target's model)."""
    cells = CellMap(np.unique(np.rint(np.vstack([data.states, data.next_states])), axis=0))
    return lambda states: cells.cells[cells.nearest(states)].astype(np.float64)


def _trust_region(data: Transitions, periodic: tuple[bool, ...]) -> Callable[[np.ndarray], np.ndarray]:
    """Whether states lie within the samples' range widened by :data:`TRUST` widths (angles: anywhere)."""
    seen = np.vstack([data.states, data.next_states])
    low, high = seen.min(axis=0), seen.max(axis=0)
    width = high - low
    low, high = low - TRUST * width, high + TRUST * width
    free = np.asarray(periodic, bool)
    low[free], high[free] = -np.inf, np.inf
    return lambda states: np.all((states >= low) & (states <= high), axis=1)


__all__ = ["TRUST", "ApprenticeFQISamples", "SampleModelPolicy"]
