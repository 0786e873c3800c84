"""``ta-tl``: Target Apprentice TL, the paper's rule as a method.

:class:`TATL` fits the target apprentice ``s' = W phi(s) + B a`` by Algorithm 2
(``tatl_mj.transfer.apprentice``) and returns Algorithm 1's policy
(``tatl_mj.transfer.algorithm1``) built on it.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import ClassVar

import numpy as np

from tatl_mj.description import TaskDescription
from tatl_mj.transfer.algorithm1 import DiscreteTATLPolicy, TATLPolicy
from tatl_mj.transfer.apprentice import Apprentice, fit_apprentice, learn_apprentice
from tatl_mj.transfer.features import Features, FeaturesSpec, check_features, make_features
from tatl_mj.transfer.method import Policy, TransferProblem
from tatl_mj.transfer.placebo import SOURCES
from tatl_mj.transitions import Transitions
from tatl_mj.validation import Constraints, Interval, InvalidSetting, ListOf, Options, check_settings


@dataclasses.dataclass(frozen=True)
class TATL:
    """Target Apprentice TL, the paper's rule: apprentice by Algorithm 2, policy by Algorithm 1.

    Attributes:
      apprentice: basis phi of the apprentice s' = W phi(s) + B a (a features spec,
        ``tatl_mj.transfer.features.make_features``).
      ridge: ridge of the apprentice's least squares (0: plain least squares).
      zeta: Algorithm 2's threshold; the apprentice grows by ``batch`` samples until
        the utility gap is <= zeta. None fits it on every sample.
      gap: ``"absolute"``, the paper's one-sided U_M - U_Mhat <= zeta (in return
        units), or ``"relative"``, |U_M - U_Mhat| / |U_M| <= zeta.
      batch: Algorithm 2's sample increment (None: all samples at once).
      utility_episodes: Algorithm 2's k trials: how many episodes of the projected
        source policy U_M (real target, counted against the method) and U_Mhat (the
        apprentice) average over; None: the experiment's evaluation protocol's.
      actions: ``"discrete"``: the action is snapped to the target's discrete
        action set, the one the FQI baselines choose from, so every method is
        compared within the same actions; ``"continuous"``: any value within the
        actuator limits (a labelled variant).
      adaptive_actions: an explicit admissible set A_ad (values of a one-dimensional
        actuator) to snap to instead.
      source: ``"trained"``, the source Q of Phase I, or ``"placebo"``, an untrained
        one of its shape (``tatl_mj.transfer.placebo``): the placebo-source ablation.
    """

    apprentice: dict = dataclasses.field(default_factory=lambda: {"kind": "linear"})
    ridge: float = 0.0
    zeta: float | None = 0.1
    gap: str = "absolute"
    batch: int | None = None
    utility_episodes: int | None = None
    actions: str = "discrete"
    adaptive_actions: tuple[float, ...] = ()
    source: str = "trained"
    name: str = "ta-tl"

    constraints: ClassVar[Constraints] = {
        "apprentice": [FeaturesSpec()],
        "ridge": [Interval(float, 0)],
        "zeta": [None, Interval(float, 0, closed="right")],
        "gap": [Options("absolute", "relative")],
        "batch": [None, Interval(int, 1)],
        "utility_episodes": [None, Interval(int, 1)],
        "actions": [Options("discrete", "continuous")],
        "adaptive_actions": [ListOf(Interval(float))],
        "source": [Options(*SOURCES)],
    }

    def __post_init__(self) -> None:
        check_settings(self)

    @property
    def privileges(self) -> tuple[str, ...]:
        """``reward function`` with Algorithm 2 on (``zeta`` set): its U_Mhat scores the apprentice's
        predicted states with the target task's own reward function, states no target episode visited."""
        return ("reward function",) if self.zeta is not None else ()

    def check(self, source: TaskDescription, target: TaskDescription) -> None:
        """Settings that need the tasks' descriptions (basis size, actuator)."""
        check_features(type(self).__name__, "apprentice", self.apprentice, target.state_dim)
        if self.adaptive_actions and target.discrete:
            raise InvalidSetting(f"{type(self).__name__}.adaptive_actions apply to a continuous actuator only")

    def features(self, target: TaskDescription) -> Features:
        return make_features(self.apprentice, target.state_dim)

    def fit_apprentice(self, problem: TransferProblem, target_samples: Transitions) -> tuple[Apprentice, int]:
        """The apprentice on ``target_samples``: by Algorithm 2 where the problem can evaluate
        the utility gap and ``zeta`` is set, else on every sample. Returns it and the samples used."""
        target = problem.target
        actions = target.action_values
        periodic = target.periodic if any(target.periodic) else None
        if self.zeta is None or not problem.has_utility_gap:
            apprentice = fit_apprentice(
                target_samples.states,
                actions[target_samples.actions],
                target_samples.next_states,
                self.features(target),
                self.ridge,
                periodic=periodic,
            )
            return apprentice, len(target_samples)
        learned = learn_apprentice(
            target_samples,
            actions,
            self.features(target),
            functools.partial(problem.utility_gap, kind=self.gap, episodes=self.utility_episodes),
            self.zeta,
            self.batch or len(target_samples),
            self.ridge,
            periodic=periodic,
            gaps=self._known_gaps(problem, target_samples),
            # Sizes ahead of need are rolled out only where that costs about one rollout.
            utility_gaps=(
                functools.partial(problem.utility_gaps, kind=self.gap, episodes=self.utility_episodes)
                if problem.model_returns
                else None
            ),
        )
        # Every budget's Algorithm 2 uses U_M, even one whose gaps were all known:
        # the problem counts its real-target rollouts against this budget.
        assert problem.target_return is not None
        more = {} if self.utility_episodes is None else {"episodes": self.utility_episodes}
        problem.target_return(problem.projected_source_policy(), **more)
        return learned

    def _known_gaps(self, problem: TransferProblem, target_samples: Transitions) -> dict[int, float]:
        """Algorithm 2's gaps by head size found at the budgets of this run so far.

        A later budget keeps the earlier samples as its head, so its heads' fits
        and gaps are theirs (the problem's hooks are functions of their
        arguments): found once, its scan skips the sizes that missed zeta.
        """
        key = ("ta-tl-gaps", id(self))
        kept = problem.replays.get(key)
        longer, gaps = target_samples, {}
        if kept is not None and kept[0] is self:
            seen, found = kept[1], kept[2]
            m = min(len(seen), len(target_samples))
            if _same_data(seen.head(m), target_samples.head(m)):
                longer = seen if len(seen) > len(target_samples) else target_samples
                gaps = {n: gap for n, gap in found.items() if longer is seen or n <= m}
        problem.replays[key] = (self, longer, gaps)
        return gaps

    def learn(self, problem: TransferProblem, target_samples: Transitions) -> Policy:
        apprentice, used = self.fit_apprentice(problem, target_samples)
        # Algorithm 2's apprentice is the fit on the first ``used`` samples alone, so a
        # later budget of the same run that keeps the same samples learns this very
        # policy: it gets the same object back, which is evaluated once (run_method).
        key, kept_samples = ("ta-tl", id(self), used), target_samples.head(used)
        kept = problem.replays.get(key)
        if kept is not None and kept[0] is self and _same_data(kept[1], kept_samples):
            return kept[2]
        policy = self._policy(problem, apprentice, used)
        problem.replays[key] = (self, kept_samples, policy)
        return policy

    def _policy(self, problem: TransferProblem, apprentice: Apprentice, used: int) -> Policy:
        target = problem.target
        common = dict(
            source_q=problem.source_q,
            mapping=problem.mapping,
            source_step=problem.source_step,
            apprentice=apprentice,
            source_actions=problem.source.action_values,
            target_actions=target.action_values,
            target_low=target.action_low,
            target_high=target.action_high,
            adaptive_actions=self.admissible_actions(target),
            samples_used=used,
        )
        return DiscreteTATLPolicy(**common) if target.discrete else TATLPolicy(**common)

    def admissible_actions(self, target: TaskDescription) -> np.ndarray | None:
        """The set the action is snapped to: A_ad if given, the target's discrete
        action set for ``actions = "discrete"``, else None (clipped only)."""
        if self.adaptive_actions:
            return np.asarray(self.adaptive_actions, dtype=np.float64).reshape(-1, 1)
        if self.actions == "discrete" and not target.discrete:
            return np.asarray(target.action_values, dtype=np.float64)
        return None


def _same_data(a: Transitions, b: Transitions) -> bool:
    """The fields an apprentice is fitted on are equal."""
    return all(np.array_equal(getattr(a, f), getattr(b, f)) for f in ("states", "actions", "next_states"))


__all__ = ["TATL"]
