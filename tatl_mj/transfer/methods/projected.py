"""``projected-source``: the mapped source policy as it is, a reference that learns nothing."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

from tatl_mj.transfer.method import Policy, TransferProblem
from tatl_mj.transitions import Transitions
from tatl_mj.validation import Constraints


@dataclasses.dataclass(frozen=True)
class ProjectedSource:
    """The mapped source policy pi*_S(chi_plus(s_T)) without adaptation: a reference, no target samples."""

    name: str = "projected-source"
    uses_samples = False  # evaluated once, whatever the budget
    constraints: ClassVar[Constraints] = {}  # no settings

    def learn(self, problem: TransferProblem, target_samples: Transitions) -> Policy:
        return problem.projected_source_policy()


__all__ = ["ProjectedSource"]
