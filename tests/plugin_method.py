"""A user's own transfer method, as `tatl run --methods plugin_method:ZeroTorque` loads it."""

import dataclasses
from typing import ClassVar

import numpy as np

from tatl_mj.validation import Constraints, Interval, check_settings


@dataclasses.dataclass(frozen=True)
class ZeroTorque:
    """Ignores the source entirely: always the middle action (no torque or force on physics targets)."""

    name: str = "zero"

    def learn(self, problem, target_samples):
        target = problem.target  # the target task's description (tatl_mj.suite.describe)
        middle = target.n_actions // 2
        if target.discrete:  # a task that takes action indices (the grid world)
            return lambda states: np.full(len(states), middle)
        value = target.action_values[middle]
        return lambda states: np.repeat(value[None], len(states), axis=0)


@dataclasses.dataclass(frozen=True)
class Broken:
    """Fails in every worker, on purpose: a run with it must not look successful."""

    name: str = "broken"

    def learn(self, problem, target_samples):
        raise RuntimeError("deliberately broken plug-in")


@dataclasses.dataclass(frozen=True)
class FixedAction:
    """Always the action of one index (None: the middle one); declares its settings' constraints
    as the built-ins do, so a spec's bad ``index`` stops the load in one line."""

    index: int | None = None
    name: str = "fixed"

    constraints: ClassVar[Constraints] = {"index": [None, Interval(int, 0)]}

    def __post_init__(self):
        check_settings(self)

    def learn(self, problem, target_samples):
        target = problem.target
        index = target.n_actions // 2 if self.index is None else min(self.index, target.n_actions - 1)
        if target.discrete:
            return lambda states: np.full(len(states), index)
        value = target.action_values[index]
        return lambda states: np.repeat(value[None], len(states), axis=0)


@dataclasses.dataclass(frozen=True)
class SourcePolicy:
    """Transfer with nothing learned on the target: the source's greedy policy through the mapping.
    Its source-free ablation is :class:`ZeroTorque` (the same nothing, without the source)."""

    name: str = "source-policy"

    def learn(self, problem, target_samples):
        return problem.projected_source_policy()


@dataclasses.dataclass(frozen=True)
class UprightNoSource(ZeroTorque):
    """Declares its roles as a built-in does: no source, and the source-free ablation of ``ta-tl``."""

    name: str = "upright-no-source"
    uses_source = False
    ablation_of = ("ta-tl",)


@dataclasses.dataclass(frozen=True)
class ClaimsAblation(ZeroTorque):
    """Declares itself ``ta-tl``'s source-free ablation without declaring that it uses no source."""

    name: str = "claims-ablation"
    ablation_of = ("ta-tl",)


class WrongShape:
    """A policy that answers three values per state, whatever the target takes: refused by the
    rehearsal before any source work."""

    name: str = "wrong-shape"

    def learn(self, problem, target_samples):
        return lambda states: np.zeros((len(states), 3))
