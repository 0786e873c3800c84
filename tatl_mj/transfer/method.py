"""The plug-in interface: what a transfer method gets, and what it must return.

A method is an object with a ``name`` and ``learn(problem, target_samples) -> Policy``
(the :class:`TransferMethod` protocol), in the scikit-learn style: its settings go
to its constructor (``TATL(zeta=0.1, apprentice={"kind": "linear"})``), the data to
``learn``. :class:`TransferProblem` holds the problem only: the source's Q-function
and simulator step, the inter-task mapping, both tasks' descriptions, and
evaluation hooks any method may call (so Algorithm 2's utility gap is available to
every method, built-in or plug-in). ``target_samples`` are the target transitions
the method is allowed to see (its budget); a method must not step the target any
other way (the hooks evaluate policies; they never hand out transitions).

The built-ins live in ``tatl_mj.transfer.methods`` (``TATL``, the paper's
Algorithms 1 and 2, in ``methods.tatl``; ``UMATL`` and ``RL`` in
``methods.target_fqi``); ``tatl_mj.transfer.registry`` names every built-in. To
compare your own method, pass an instance of it next to these to the experiment runner.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any, Callable, NoReturn, Protocol, Sequence, runtime_checkable

import numpy as np

from tatl_mj.description import TaskDescription
from tatl_mj.policy import StatePolicy
from tatl_mj.transfer.algorithm1 import PremiseStep, SourceStep
from tatl_mj.transfer.fqi import QFunction
from tatl_mj.transfer.intertask_mapping import Mapping
from tatl_mj.transitions import Transitions

Policy = Callable[[np.ndarray], np.ndarray]
"""Batched target policy: (N, dT) states -> (N, mT) action values, or (N,) indices for a discrete target."""

Model = Any
"""A target model standing in for the simulator: ``predict(states, action_values) -> next_states``."""


@dataclasses.dataclass(frozen=True, eq=False)
class TransferProblem:
    """Everything a transfer method may use besides the target samples.

    Attributes:
      source_q: Q_S learned on the source (Phase I).
      mapping: chi / chi_plus between the state spaces (Phase II).
      source_step: one batched source-simulator step, (N, dS), (N,) indices -> (N, dS).
      source, target: the two tasks' descriptions (``tatl_mj.suite.describe``): state
        names and periodic coordinates, action values (row i of the source's
        corresponds to row i of the target's, Assumption 1), actuator limits,
        control steps, a known model where there is one.
      seed: seeds every random choice a method makes.
      target_return: U_M(pi), the mean return of a policy on the real target under
        the experiment's evaluation protocol (no target samples are handed out);
        ``target_return(policy, episodes=k)`` over its first k episodes' starts.
      model_return: U_Mhat(pi), the same policy's mean return when ``model`` stands
        in for the target (the target task's reward and end conditions applied to
        the model's predicted states); None where the task has no such reward.
      model_returns: ``model_return`` of several models in one call, each value
        what ``model_return`` gives it (one rollout of them side by side); None:
        ``model_return`` is asked model by model.
      target_step: the real target simulator's one step, (N, dT) states, (N, mT)
        action values -> (N, dT); for oracle ablations only (it is not a sample
        budget a fair method may use).
      policy_samples: ``policy_samples(policy, n)`` -> n target transitions from
        episodes of ``policy`` from the target's start distribution: the paper's
        protocol for the apprentice's data ("execute pi*(S) in the target from
        random starts"), for a method that spends its budget that way instead of
        on the shared random-policy stream.
      target_reward: the target task's own reward and end condition of a step,
        ``(states, action_indices, next_states) -> (rewards (N,), absorbing (N,))``,
        for a learner that scores a model's transitions (``apprentice-fqi``).
      reset_samples: ``reset_samples(n)`` -> n one-step target transitions from
        states spread over the target's reset box with random actions (the
        ``reset`` data protocol; privileged: a simulator reset a robot lacks).
      episode_samples: ``episode_samples(policy, n, round)`` -> n transitions of
        whole episodes of an index ``policy`` (None: uniformly random actions)
        from the target's own start states, the resets seeded by ``round``
        (the ``online`` data protocol; no resets to chosen states).
      charge: ``charge(n)`` counts n real-target transitions against the method that
        it learns from again without asking a hook for them: an earlier budget's
        collection that it replays, because its own run would have collected the
        very same data (None: nothing may be replayed).

    Every real-target transition a hook hands out or rolls out is counted
    against the method (``target_transitions`` in the records).
    """

    source_q: QFunction
    mapping: Mapping
    source_step: SourceStep
    source: TaskDescription
    target: TaskDescription
    seed: int = 0
    target_return: Callable[[Policy], float] | None = None
    model_return: Callable[[Model, Policy], float] | None = None
    model_returns: Callable[[Sequence[Model], Policy], Sequence[float]] | None = None
    target_step: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
    policy_samples: Callable[[Policy, int], Transitions] | None = None
    target_reward: Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None
    reset_samples: Callable[[int], Transitions] | None = None
    episode_samples: Callable[[Callable | None, int, int], Transitions] | None = None
    charge: Callable[[int], None] | None = None
    # What a method keeps for a later budget of the same run (TargetFQI._online's
    # rounds, TATL's policies); not part of the problem's identity.
    replays: dict = dataclasses.field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        if self.source.n_actions != self.target.n_actions:
            raise ValueError(
                f"the source has {self.source.n_actions} actions and the target {self.target.n_actions}; "
                "Assumption 1 pairs them one to one"
            )

    @property
    def n_actions(self) -> int:
        return self.target.n_actions

    def projected_source_policy(self) -> Policy:
        """pi_hat(s_T) = pi*_S(chi_plus(s_T)), carried to the target action of the same index.

        The same object on every call, so that hooks may cache by policy (the
        paper-protocol data of ``policy_samples`` is collected once per problem).
        """
        return self._projected_source_policy

    @functools.cached_property
    def _projected_source_policy(self) -> Policy:
        source_q, mapping, target = self.source_q, self.mapping, self.target

        def policy(states: np.ndarray) -> np.ndarray:
            index = source_q.greedy(mapping.chi_plus(states))
            return index if target.discrete else target.action_values[index]

        # A function of the state alone: a tabular target's sampler asks it once per cell.
        return StatePolicy(policy)

    @property
    def has_utility_gap(self) -> bool:
        """Whether Algorithm 2's utility gap can be computed (both hooks given)."""
        return self.target_return is not None and self.model_return is not None

    def utility_gap(self, model: Model, kind: str = "absolute", episodes: int | None = None) -> float:
        """Algorithm 2's gap between U_M(pi) and U_Mhat(pi) for the projected source policy.

        ``"absolute"`` (the paper's): U_M - U_Mhat, compared one-sided with zeta;
        ``"relative"``: |U_M - U_Mhat| / |U_M|. Both come from the same start
        states (the problem's hooks say which), ``episodes`` of them (Algorithm 2's
        k trials; None: the hooks' own number, the evaluation protocol's), and U_M's
        real-target rollouts are counted against the method that asks. A model
        whose rollout diverges is as far from the target as can be (1e300).
        """
        return self.utility_gaps([model], kind, episodes)[0]

    def utility_gaps(self, models: Sequence[Model], kind: str = "absolute", episodes: int | None = None) -> list[float]:
        """:meth:`utility_gap` of each of ``models``, their U_Mhat in one ``model_returns`` call where given."""
        if not self.has_utility_gap:
            raise ValueError("this problem has no target_return/model_return hooks: no utility gap")
        assert self.target_return is not None and self.model_return is not None
        policy = self.projected_source_policy()
        # Only a chosen number of episodes is passed on: hooks written before the
        # keyword existed keep working with their own.
        more = {} if episodes is None else {"episodes": episodes}
        u_true = float(self.target_return(policy, **more))
        if self.model_returns is not None:
            u_hats = list(self.model_returns(models, policy, **more))
        else:
            u_hats = [self.model_return(model, policy, **more) for model in models]
        return [_gap(u_true, u_hat, kind) for u_hat in u_hats]


def _gap(u_true: float, u_hat: float, kind: str) -> float:
    if not math.isfinite(u_hat):
        return 1e300
    if kind == "relative":
        return abs(u_true - u_hat) / max(abs(u_true), 1e-9)
    return u_true - u_hat


@runtime_checkable
class TransferMethod(Protocol):
    """A transfer method that the experiments can compare: a ``name`` and ``learn``.

    The experiments also read these optional attributes, with these defaults
    (:func:`contract` reads them, the one place that does):

    - ``check(source, target)``: raises ValueError (one line) where the method
      cannot run on these tasks' descriptions; called when a spec is loaded and
      before a run starts (default: none);
    - ``uses_samples``: False for a reference that learns nothing from the target
      (learned and evaluated once, counts 0; default True);
    - ``data``: where its transitions come from, ``"shared"`` (the first n of
      the shared random-policy stream, counted as used) or its own (anything
      else: only what the problem's hooks hand out is counted; default "shared");
    - ``source``: ``"trained"`` or ``"placebo"`` (the problem then holds an
      untrained source Q of the trained one's shape; default "trained");
    - ``uses_source``: False for a method that reads no source Q, mapping or source
      simulator (the problem then withholds them: reading one raises
      :class:`SourceWithheld`), so experiments that share its target, data and
      random streams and differ only in their mapping get the same record, and
      ``tatl run`` computes it once, and the verdicts count it as source-free (default True);
    - ``ablation_of``: the methods it is the source-free ablation of, each named as a
      spec's table builds it (a built-in's name, or a plug-in's ``module:attribute``):
      a transfer method built from one of them is judged against it where the spec
      names no ``ablation`` of its own (default none; only a method with
      ``uses_source`` False may declare any);
    - ``baseline``: True for a comparison method (the reports compare every other
      method with the experiment's best baseline; default False);
    - ``privileged``: True for a method that uses what a robot in the target lacks:
      simulator resets to chosen states, the target's reward function at states of its
      choosing, or the target's true model (default False);
    - ``privileges``: which of those it uses, named from :data:`PRIVILEGES` (default: none;
      a method that says ``privileged`` and names none holds ``"unnamed"``). A verdict credits
      transfer only against a comparator whose privileges the method holds too
      (``tatl_mj.experiments.report.privileges.credits``);
    - on the returned policy, ``samples_used``: how many of the n shared samples
      it kept (Algorithm 2 may stop early; default n);
    - on the returned policy, ``decide_together(policies)``: called on the first of
      several policies evaluated side by side (a learning curve's budgets), a
      :data:`JointDecisions` that gives each block's states exactly the actions its
      policy gives them alone, sharing work between them, or None where they cannot
      (:func:`joint_decisions` reads it; default: each policy is called on its own);
    - on the returned policy, ``premise_step(states)``: the very decision ``policy(states)``
      gives, as a :class:`~tatl_mj.transfer.algorithm1.PremiseStep` with what the theorem's
      premises are measured by (the request before clipping, s_hat_next, its model's
      prediction), and attribute ``mapping`` (and ``apprentice`` where the step carries no
      prediction); a policy with it is TA-TL's and its evaluation measures the premises
      (:func:`premise_probe` reads it; default: not measured). Its optional class attribute
      ``premise_measures`` names which (``tatl_mj.experiments.run.premises.measures_of``);
    - on the returned policy, ``premise_together(policies)``: ``decide_together``'s
      counterpart for the premises, a :data:`JointPremises` whose steps' actions are
      exactly ``decide_together``'s (:func:`joint_premises` reads it; default: each
      observed policy's ``premise_step`` on its own).

    ``uses_source``, ``ablation_of``, ``baseline``, ``privileges`` and ``source`` are the
    method's roles: the runner, the verdicts and the reports read them from the built
    method (a role that depends on a setting is a property of the instance).

    A method class declares what each of its settings admits in a class-level table,
    ``constraints`` (``tatl_mj.validation``; the built-ins' in their modules): a spec's
    settings are checked and converted against it before the class is called
    (:func:`tatl_mj.transfer.registry.resolve`), and a class that calls
    ``validation.check_settings(self)`` in ``__post_init__`` is checked when built
    in Python too.
    """

    name: str

    def learn(self, problem: TransferProblem, target_samples: Transitions) -> Policy: ...


PRIVILEGES = {
    "resets": "simulator resets to states it chooses",
    "reward function": "the target's reward function at states no target episode visited",
    "reset box": "model states drawn from the target's whole reset box",
    "true model": "the target's true model, or its simulator stepped from a chosen state",
    "unnamed": "a privilege its method declares without naming it",
}
"""The target resources a robot lacks, by name: a method's ``privileges`` come from here."""


@dataclasses.dataclass(frozen=True)
class Contract:
    """What the experiments read of a method beyond ``name`` and ``learn`` (see
    :class:`TransferMethod`), with its defaults filled in."""

    uses_samples: bool = True
    data: str = "shared"
    source: str = "trained"
    check: Callable[[TaskDescription, TaskDescription], None] | None = None
    uses_source: bool = True
    ablation_of: tuple[str, ...] = ()
    baseline: bool = False
    privileges: frozenset[str] = frozenset()

    @property
    def privileged(self) -> bool:
        return bool(self.privileges)


def contract(method: Any) -> Contract:
    """``method``'s optional hooks and attributes, defaults where it has none; ValueError
    (one line) where its roles contradict each other."""
    declared = Contract(
        uses_samples=bool(getattr(method, "uses_samples", True)),
        data=str(getattr(method, "data", "shared")),
        source=str(getattr(method, "source", "trained")),
        check=getattr(method, "check", None),
        uses_source=bool(getattr(method, "uses_source", True)),
        ablation_of=_names(method, getattr(method, "ablation_of", ())),
        baseline=bool(getattr(method, "baseline", False)),
        privileges=_privileges(method),
    )
    if declared.ablation_of and declared.uses_source:
        # A win over an ablation that reads the source would not be a win of the source.
        raise ValueError(
            f"method {getattr(method, 'name', method)!r} declares ablation_of {list(declared.ablation_of)} "
            "but uses the source: a source-free ablation declares uses_source = False"
        )
    return declared


def _privileges(method: Any) -> frozenset[str]:
    declared = getattr(method, "privileges", ()) or ()
    names = (declared,) if isinstance(declared, str) else tuple(declared)
    if isinstance(declared, str) or any(n not in PRIVILEGES for n in names):
        raise ValueError(
            f"method {getattr(method, 'name', method)!r} declares privileges {list(names)!r}: "
            f"each must be one of {sorted(PRIVILEGES)}"
        )
    if not names and getattr(method, "privileged", False):
        return frozenset({"unnamed"})
    return frozenset(names)


def _names(method: Any, value: Any) -> tuple[str, ...]:
    if not isinstance(value, (tuple, list)) or not all(isinstance(v, str) for v in value):
        raise ValueError(
            f"method {getattr(method, 'name', method)!r}: ablation_of must be a tuple of method names, got {value!r}"
        )
    return tuple(value)


class SourceWithheld(RuntimeError):
    """A method that declares ``uses_source = False`` read the source Q, mapping or source simulator."""


@dataclasses.dataclass(frozen=True)
class Withheld:
    """Stands in for ``problem.<field>`` for a method without a source: any use raises
    :class:`SourceWithheld`, so its record cannot depend on what it does not declare."""

    field: str

    def _refuse(self) -> NoReturn:
        raise SourceWithheld(f"problem.{self.field} was read by a method that declares uses_source = False")

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__"):  # copy, pickle and repr probe dunders: answer as a plain object would
            raise AttributeError(name)
        self._refuse()

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        self._refuse()


JointDecisions = Callable[[list[int], list[np.ndarray]], list[np.ndarray]]
"""Several policies deciding at once: ``decide(blocks, states)`` -> for each block b and its
(N_b, dT) states, ``policies[b](states)``."""


def joint_decisions(policies: Sequence[Any]) -> JointDecisions | None:
    """The first policy's ``decide_together(policies)`` where it has that hook (see
    :class:`TransferMethod`), else None: the policies are then called one by one."""
    hook = getattr(policies[0], "decide_together", None) if policies else None
    return None if hook is None else hook(policies)


def premise_probe(policy: Any) -> Callable[[np.ndarray], PremiseStep] | None:
    """``policy``'s ``premise_step`` hook (see :class:`TransferMethod`) where it has one and
    the ``mapping`` it is measured by, else None (no premises measured)."""
    hook = getattr(policy, "premise_step", None)
    if hook is None or getattr(policy, "mapping", None) is None:
        return None
    return hook


JointPremises = Callable[[list[int], list[np.ndarray]], list[PremiseStep]]
""":data:`JointDecisions` with each block's :class:`PremiseStep` instead of its actions."""


def joint_premises(policies: Sequence[Any]) -> JointPremises | None:
    """The first policy's ``premise_together(policies)`` where it has that hook (see
    :class:`TransferMethod`), else None: each policy's ``premise_step`` on its own."""
    hook = getattr(policies[0], "premise_together", None) if policies else None
    return None if hook is None else hook(policies)


def samples_used(policy: Any, budget: int) -> int:
    """How many of the ``budget`` shared samples ``policy`` kept (its ``samples_used``, else all)."""
    reported = getattr(policy, "samples_used", None)
    return int(budget) if reported is None else int(reported)


__all__ = [
    "Contract",
    "JointDecisions",
    "JointPremises",
    "Model",
    "PRIVILEGES",
    "Policy",
    "SourceWithheld",
    "TransferMethod",
    "TransferProblem",
    "Withheld",
    "contract",
    "joint_decisions",
    "joint_premises",
    "premise_probe",
    "samples_used",
]
