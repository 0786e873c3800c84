"""The tatl-mj task suite, loaded like dm_control's.

>>> from tatl_mj import suite
>>> env = suite.load("cartpole", "balance", task_kwargs={"random": 0})
>>> timestep = env.reset()

Every task speaks dm_env. Physics tasks are ``dm_control.rl.control.Environment``
instances whose observation is ``{"state": the paper's state vector}``.

A domain is named by its key in ``DOMAINS`` (the built-ins) or, for a user's own,
by an import path ``"module:attribute"`` (``"mypkg.domains:point_mass"``): the
attribute is a module or any object that provides what a built-in domain module
does (``TASKS``, ``describe``, ``ACTIONS``; see docs/extending.md). Every function
here takes either; an import path is imported on first use in each process
(so a worker process resolves it the same way as the process that started it)
and checked against that contract (:func:`domain`).
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Mapping
from types import ModuleType
from typing import Any

import dm_env
import numpy as np

from tatl_mj import plugins
from tatl_mj.description import TaskDescription
from tatl_mj.suite import bicycle, cartpole, contexts, gridworld, mountain_car, pendulum
from tatl_mj.suite.contexts import ContextKey as ContextKey
from tatl_mj.suite.contexts import ContextSampler as ContextSampler
from tatl_mj.suite.contexts import ContextSpec

DOMAINS: dict[str, ModuleType] = {
    "cartpole": cartpole,
    "pendulum": pendulum,
    "mountain_car": mountain_car,
    "bicycle": bicycle,
    "gridworld": gridworld,
}

ALL_TASKS: tuple[tuple[str, str], ...] = tuple(
    (domain, task) for domain, module in DOMAINS.items() for task in module.TASKS
)


class DomainError(ValueError):
    """A domain name that resolves to no domain; the message says what was expected."""


def _valid_domains() -> str:
    return f"valid domains: {sorted(DOMAINS)}, or your own as 'module:attribute'"


def check_domain(obj: Any, name: str) -> None:
    """Raises DomainError unless ``obj`` provides the domain contract: ``TASKS`` (a
    non-empty table of task name -> factory), ``describe`` (callable) and ``ACTIONS``."""
    tasks = getattr(obj, "TASKS", None)
    if not isinstance(tasks, Mapping) or not tasks:
        raise DomainError(
            f"{name!r} is not a domain: it needs TASKS, a non-empty table of task name -> factory, "
            f"got {type(tasks).__name__ if tasks is not None else 'none'}"
        )
    bad = [task for task, factory in tasks.items() if not isinstance(task, str) or not callable(factory)]
    if bad:
        raise DomainError(f"{name!r} is not a domain: TASKS[{bad[0]!r}] must be a callable factory under a str name")
    if not callable(getattr(obj, "describe", None)):
        raise DomainError(f"{name!r} is not a domain: it needs describe(task, **task_kwargs) -> TaskDescription")
    if getattr(obj, "ACTIONS", None) is None:
        raise DomainError(f"{name!r} is not a domain: it needs ACTIONS, the discrete action set")


@functools.lru_cache(maxsize=None)  # per process; a failed import is not cached (it raised)
def _imported(path: str) -> Any:
    if ":" not in path:
        raise DomainError(f"domain {path!r}: an import path must be 'module:attribute'; {_valid_domains()}")
    obj = plugins.load(path, "domain", DomainError)
    check_domain(obj, path)
    return obj


def domain(name: str) -> Any:
    """The domain module (or object) named ``name``: a key of ``DOMAINS`` or ``"module:attribute"``.

    Raises DomainError (a ValueError) with one line: an unknown name (listing the
    valid ones), a module that cannot be imported, a missing attribute, or an
    object that is not a domain (:func:`check_domain`).
    """
    if not isinstance(name, str):
        raise DomainError(f"a domain name must be a string, got {name!r}")
    if name in DOMAINS:
        return DOMAINS[name]
    if ":" in name:
        return _imported(name)
    raise DomainError(f"unknown domain {name!r}; {_valid_domains()}")


_domain = domain


def _factory(domain: str, task: str) -> Any:
    module = _domain(domain)
    if task not in module.TASKS:
        raise ValueError(f"unknown task {task!r} for domain {domain!r}; valid tasks: {sorted(module.TASKS)}")
    return module.TASKS[task]


def _check_task_kwargs(domain: str, task: str, kwargs: dict[str, Any]) -> None:
    accepted = [
        name
        for name, p in inspect.signature(_factory(domain, task)).parameters.items()
        if name != "environment_kwargs" and p.kind is not p.VAR_KEYWORD
    ]
    unknown = sorted(set(kwargs) - set(accepted))
    if unknown:
        raise ValueError(f"unknown task_kwargs {unknown} for {domain}/{task}; valid: {sorted(accepted)}")


def describe(domain: str, task: str, task_kwargs: dict[str, Any] | None = None) -> TaskDescription:
    """Static facts about ``domain/task`` (state names, periodic coordinates, action
    values, limits, control step, a known model), without building or stepping it."""
    kwargs = dict(task_kwargs or {})
    _check_task_kwargs(domain, task, kwargs)
    kwargs.pop("random", None)
    kwargs.pop("time_limit", None)
    return _domain(domain).describe(task, **kwargs)


def time_limit(domain: str, task: str, task_kwargs: dict[str, Any] | None = None) -> Any:
    """``domain/task``'s time limit in seconds: ``task_kwargs["time_limit"]`` as given, else its
    factory's default (``inf``: none)."""
    given = (task_kwargs or {}).get("time_limit")
    if given is not None:
        return given
    return inspect.signature(_factory(domain, task)).parameters["time_limit"].default


def load(
    domain: str,
    task: str,
    task_kwargs: dict[str, Any] | None = None,
    environment_kwargs: dict[str, Any] | None = None,
) -> dm_env.Environment:
    """Returns the environment for ``domain/task``.

    ``task_kwargs`` go to the task's factory (``random`` seeds the episode,
    ``time_limit`` in seconds, and the task's own options); ``environment_kwargs``
    go to the dm_control ``Environment`` (e.g. ``flat_observation``).
    Unknown names raise ``ValueError`` listing the valid ones.
    """
    factory = _factory(domain, task)
    kwargs = dict(task_kwargs or {})
    _check_task_kwargs(domain, task, kwargs)
    random = kwargs.get("random")
    if random is not None and not isinstance(random, np.random.RandomState):
        try:
            kwargs["random"] = np.random.RandomState(random)  # what dm_control would make of it
        except (TypeError, ValueError) as error:
            raise ValueError(
                f"task_kwargs['random'] must be None, an integer seed (0 .. 2**32 - 1, or a sequence "
                f"of them) or a np.random.RandomState; got {random!r} ({error})"
            ) from None
    return factory(environment_kwargs=environment_kwargs, **kwargs)


def context_spec(domain: str, task: str) -> ContextSpec:
    """The context keys ``domain/task`` takes (its domain's ``CONTEXTS``; none if it declares none)."""
    _factory(domain, task)
    return getattr(_domain(domain), "CONTEXTS", {}).get(task, ContextSpec())


def check_context(
    domain: str, task: str, context: Any, task_kwargs: dict[str, Any] | None = None, where: str = "context"
) -> dict[str, float]:
    """The values of every context key of ``domain/task`` under ``context`` (a dict of key ->
    number; ``task_kwargs`` and the factory's defaults fill the keys it leaves out).

    Raises ValueError in one line naming the bad key and the valid keys with their
    units and ranges; nothing is built.
    """
    spec = context_spec(domain, task)
    label = f"{domain}/{task} {where}"
    given = contexts.check(spec, context, label)
    base = contexts.defaults(spec, _factory(domain, task), dict(task_kwargs or {}))
    return contexts.full(spec, base, given, label)


def task_kwargs_with_context(
    domain: str, task: str, task_kwargs: dict[str, Any] | None, values: dict[str, float]
) -> dict[str, Any]:
    """``task_kwargs`` with the context ``values`` (checked by :func:`check_context`) written in,
    for ``load``: the task built with that context."""
    return contexts.task_kwargs_with(context_spec(domain, task), dict(task_kwargs or {}), values)


def action_set(domain: str) -> np.ndarray:
    """The paper's discrete action set of a domain; ``env.step(action_set(d)[i])`` is valid."""
    return _domain(domain).ACTIONS


def discrete_action(domain: str, index: int) -> np.ndarray:
    """The actuator value of discrete action ``index`` (e.g. 0 -> -20 N for cart-pole)."""
    actions = action_set(domain)
    if isinstance(index, (bool, np.bool_)) or not isinstance(index, (int, np.integer)):
        raise ValueError(f"action index must be a whole number (0..{len(actions) - 1} for {domain}), got {index!r}")
    if not 0 <= int(index) < len(actions):
        raise ValueError(f"action index {index} out of range for {domain}; valid: 0..{len(actions) - 1}")
    return actions[int(index)]
