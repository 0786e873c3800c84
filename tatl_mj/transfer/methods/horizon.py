"""Horizon-matched TA-TL as a method: ``ta-tl-h`` and its ablations (``apprentice-upright``,
the oracle). The algorithm and its departures from the paper are described with its
policy, :mod:`tatl_mj.transfer.methods.horizon_policy`; the oracle's model is
:mod:`tatl_mj.transfer.methods.linearisation`.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from tatl_mj.description import TaskDescription
from tatl_mj.transfer.method import TransferProblem
from tatl_mj.transfer.methods.horizon_policy import REFERENCES, HorizonTATLPolicy
from tatl_mj.transfer.methods.linearisation import affine_model, linearised_parts
from tatl_mj.transfer.methods.tatl import TATL
from tatl_mj.transitions import Transitions
from tatl_mj.validation import Constraints, Interval, InvalidSetting, ListOf, Options, Text


@dataclasses.dataclass(frozen=True)
class HorizonTATL(TATL):
    """Horizon-matched TA-TL as a method (``ta-tl-h``; see the module docstring).

    The apprentice is TA-TL's (``apprentice``, ``ridge``, and Algorithm 2 through
    ``zeta``/``batch`` when the reference is the source's). Settings:

    - ``horizon``: H, target steps matched (the bicycle: 20 steps of 10 ms);
    - ``step_ratio``: dt_source / dt_target; None derives it from the two tasks'
      control steps (cart-pole 20 ms, bicycle 10 ms: 2);
    - ``weights``: diagonal of W, one per target state coordinate (empty: all ones);
    - ``reference``: ``"source"``, or ``"zero"`` for ``apprentice-upright``: the same
      controller aiming at the target's zero state, no source at all (its apprentice
      then fits every sample: Algorithm 2 is defined through the source policy);
    - ``source_zero``: names of source state coordinates set to 0 where the source
      rollout starts (an ablation: which part of the source's state hurts the
      reference); empty: none;
    - ``model``: ``"apprentice"``, or ``"oracle"``: the real target simulator's exact
      linearisation at the target's zero state (:func:`linearised`) stands in for the
      apprentice, an ablation that separates the apprentice's estimation error from
      the rule's; it uses no target samples. (Stepping the simulator itself inside
      the horizon would cost about 20 simulator calls per decision: too slow for
      long evaluations.)
    """

    horizon: int = 20
    step_ratio: float | None = None
    weights: tuple[float, ...] = ()
    # Every sample, like its source-free ablation (which has no source to run
    # Algorithm 2 with), so the pair is compared on equal data; a spec may set zeta.
    zeta: float | None = None
    reference: str = "source"
    source_zero: tuple[str, ...] = ()
    model: str = "apprentice"
    name: str = "ta-tl-h"

    constraints: ClassVar[Constraints] = {
        **TATL.constraints,
        "horizon": [Interval(int, 1, unit=" (target steps)")],
        "step_ratio": [None, Interval(float, 0, closed="right", unit=" (dt_source / dt_target)")],
        "weights": [ListOf(Interval(float, 0), not_all_zero=True)],
        "reference": [Options(*REFERENCES)],
        "source_zero": [ListOf(Text("a source state name"))],
        "model": [Options("apprentice", "oracle")],
    }

    def __post_init__(self) -> None:
        super().__post_init__()
        owner = type(self).__name__
        if self.adaptive_actions:
            raise InvalidSetting(f"{owner}.adaptive_actions is not supported (the action is clipped to the actuator)")
        for field, used in (("source_zero", bool(self.source_zero)), ("source = 'placebo'", self.source == "placebo")):
            if used and self.reference != "source":
                raise InvalidSetting(f"{owner}.{field} needs reference = 'source' (the zero reference has no source)")

    @property
    def uses_samples(self) -> bool:
        return self.model != "oracle"

    @property
    def uses_source(self) -> bool:
        """False for ``apprentice-upright`` (the zero reference reads no source at all)."""
        return self.reference == "source"

    @property
    def ablation_of(self) -> tuple[str, ...]:
        """The zero reference is ``ta-tl-h``'s ablation: the same controller and apprentice without the source."""
        return () if self.uses_source else ("ta-tl-h",)

    @property
    def privileges(self) -> tuple[str, ...]:
        """``true model`` for ``model = "oracle"``: it steps the real target simulator from a chosen
        state (the zero state) to linearise it, which a robot cannot; and Algorithm 2's, as ``ta-tl``."""
        return (("true model",) if self.model == "oracle" else ()) + super().privileges

    def check(self, source: TaskDescription, target: TaskDescription) -> None:
        super().check(source, target)
        owner = type(self).__name__
        if target.discrete:
            raise ValueError(f"{owner} needs a continuous actuator; {target.domain}/{target.task} takes indices")
        if self.weights and len(self.weights) != target.state_dim:
            raise ValueError(
                f"{owner}.weights must have {target.state_dim} entries ({', '.join(target.state_names)}), "
                f"got {len(self.weights)}"
            )
        unknown = [n for n in self.source_zero if n not in source.state_names]
        if unknown:
            raise ValueError(
                f"{owner}.source_zero names {unknown[0]!r}; valid choices: {list(source.state_names)} "
                f"({source.domain}/{source.task}'s state)"
            )
        if self.step_ratio is None and (source.control_timestep is None or target.control_timestep is None):
            raise ValueError(f"{owner}.step_ratio is needed: the tasks' control steps have no duration")

    def learn(self, problem: TransferProblem, target_samples: Transitions) -> HorizonTATLPolicy:
        self.check(problem.source, problem.target)
        target = problem.target
        if self.model == "oracle":
            if problem.target_step is None:
                raise ValueError(f"{type(self).__name__}(model='oracle') needs the problem's target_step")
            parts = linearised_parts(problem.target_step, target.state_dim, target.action_dim)
            model, used, periodic, affine = affine_model(parts), None, None, parts
        else:
            fitter = self if self.reference == "source" else dataclasses.replace(self, zeta=None)
            apprentice, used = fitter.fit_apprentice(problem, target_samples)
            model, periodic, affine = apprentice.predict, apprentice.periodic, apprentice.affine()
        ratio = self.step_ratio
        if ratio is None:
            ratio = problem.source.control_timestep / target.control_timestep
        source = (
            dict(
                source_q=problem.source_q,
                mapping=problem.mapping,
                source_step=problem.source_step,
                target_actions=target.action_values,
                source_zero=tuple(problem.source.state_names.index(n) for n in self.source_zero),
            )
            if self.reference == "source"
            else {}
        )
        return HorizonTATLPolicy(
            model,
            target.action_low,
            target.action_high,
            horizon=self.horizon,
            step_ratio=ratio,
            weights=np.asarray(self.weights, dtype=np.float64) if self.weights else None,
            reference=self.reference,
            periodic=periodic if periodic and any(periodic) else None,
            affine=affine,
            samples_used=used,
            admissible=self.admissible_actions(target),
            **source,
        )


__all__ = ["HorizonTATL"]
