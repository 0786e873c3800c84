"""``apprentice-fqi``: TA-TL's own apprentice without the source, a **privileged** ablation of ``ta-tl``.

It fits the same least-squares apprentice ``s' = W phi(s) + B a`` as TA-TL (the
same basis, on the same target samples), then solves the target by FQI on
transitions the apprentice predicts from states spread over the target's reset
box, each scored by the target task's own reward and end condition. No source
Q, mapping or source simulator is used anywhere. It is privileged: it queries the
target's reward function at states of its choosing, from the whole reset box
(``privileges``: ``reward function``, ``reset box``), which a robot lacks and
``ta-tl`` does not have, so a verdict against it does not credit or discredit
transfer; the comparator that does is ``apprentice-fqi-samples``
(``tatl_mj.transfer.methods.sample_model``), which learns the reward from the
samples. The model's transitions are not target samples (they cost no
real-target step); the target samples it learns from are counted as every
method's are.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from tatl_mj.description import CellMap, TaskDescription
from tatl_mj.transfer.apprentice import Apprentice
from tatl_mj.transfer.features import FeaturesSpec, check_features
from tatl_mj.transfer.fqi import QFunction
from tatl_mj.transfer.method import TransferProblem
from tatl_mj.transfer.methods.target_fqi import TargetFQI
from tatl_mj.transfer.methods.tatl import TATL
from tatl_mj.transitions import Transitions
from tatl_mj.validation import Constraints, Interval, InvalidSetting


@dataclasses.dataclass(frozen=True)
class ApprenticeFQI(TargetFQI):
    """FQI on the apprentice's predicted transitions (source-free, model-based).

    Attributes (besides :class:`TargetFQI`'s learner settings, which a spec sets
    to the RL baseline's):
      apprentice: the apprentice's basis phi, as ``ta-tl``'s (a features spec).
      apprentice_ridge: its least squares' ridge, as ``ta-tl``'s ``ridge``.
      model_samples: how many model transitions FQI learns from.
    """

    apprentice: dict = dataclasses.field(default_factory=lambda: {"kind": "linear"})
    apprentice_ridge: float = 0.0
    model_samples: int = 20000
    name: str = "apprentice-fqi"
    ablation_of = ("ta-tl",)  # ta-tl's own apprentice, without the source
    # It scores model transitions from states spread over the target's reset box with the
    # target's own reward function (problem.target_reward): states a robot does not choose.
    privileges = ("reward function", "reset box")

    constraints: ClassVar[Constraints] = {
        **TargetFQI.constraints,
        "apprentice": [FeaturesSpec()],
        "apprentice_ridge": [Interval(float, 0)],
        "model_samples": [Interval(int, 1)],
    }

    def check(self, source: TaskDescription, target: TaskDescription) -> None:
        super().check(source, target)
        owner = type(self).__name__
        check_features(owner, "apprentice", self.apprentice, target.state_dim)
        if target.reset_low is None and not (target.discrete and target.known_model):
            raise InvalidSetting(f"{owner} needs the target's reset box; {target.domain}/{target.task} declares none")

    def fit_apprentice(self, problem: TransferProblem, data: Transitions) -> Apprentice:
        """``ta-tl``'s apprentice fitted on every sample of ``data`` (no Algorithm 2: it needs the source)."""
        tatl = TATL(apprentice=self.apprentice, ridge=self.apprentice_ridge, zeta=None)
        return tatl.fit_apprentice(problem, data)[0]

    def model_transitions(
        self, problem: TransferProblem, apprentice: Apprentice, rng: np.random.Generator
    ) -> Transitions:
        """``model_samples`` one-step transitions the apprentice predicts, from the reset box."""
        target = problem.target
        if problem.target_reward is None:
            raise ValueError(f"{type(self).__name__} needs the problem's target_reward")
        states = target.reset_states(self.model_samples, rng)
        actions = rng.integers(target.n_actions, size=len(states))
        with np.errstate(all="ignore"):
            next_states = apprentice.predict(states, target.action_values[actions])
        keep = np.all(np.isfinite(next_states), axis=1)  # a wild fit: drop what overflowed
        states, actions, next_states = states[keep], actions[keep], next_states[keep]
        if target.discrete and target.known_model is not None:
            cells = CellMap(target.known_model()[3])
            next_states = cells.cells[cells.nearest(next_states)].astype(np.float64)
        rewards, absorbing = problem.target_reward(states, actions, next_states)
        return Transitions(
            states=states,
            actions=actions,
            rewards=rewards,
            next_states=next_states,
            absorbing=absorbing,
            last=np.ones(len(states), dtype=bool),
        )

    def fit(self, problem: TransferProblem, data: Transitions, rng: np.random.Generator) -> QFunction:
        apprentice = self.fit_apprentice(problem, data)
        return self.fqi(problem, self.model_transitions(problem, apprentice, rng), rng)


__all__ = ["ApprenticeFQI"]
