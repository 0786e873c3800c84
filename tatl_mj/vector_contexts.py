"""Each simulation's context in the native vector env (``TatlVectorEnv(contexts=...)``).

A context is a ``task_kwargs``-style dict of the task's context keys
(``suite.context_spec``; docs/suite.md lists them). The vector env takes one per
env, or a :class:`~tatl_mj.suite.ContextSampler` that draws a new one at each
env's reset from its own seeded generator. What each key becomes:

- a model key (a mass, a length, a gain): the simulation's per-simulation model
  fields (``mujoco.batch``'s), as the task built with that context has them. A
  task that can write its models for many contexts at once (``write_models``,
  the pendulum's) writes them, and its schedule's step models, straight into
  the batch, whose ``set_const`` then derives the rest; any other task is built
  once per distinct context and the model fields in which it differs from the
  batch's model are copied, as :class:`tatl_mj.vector.StepModels` does for steps;
- a task key (the bicycle's rider noise and speed): a per-simulation array,
  lent to the task for each start draw (as the simulation's random stream is)
  and given to its ``controls_each`` row by row.

Every context is checked where it enters: the given ones before anything is
built, each sampled one as it is drawn.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import mujoco
import mujoco.batch
import numpy as np

from tatl_mj import suite
from tatl_mj.suite import ContextSampler

_CACHED_MODELS = 256  # distinct contexts whose model rows a vector env keeps (a sampler draws many)


class SimContexts:
    """The contexts of a vector env's ``num_envs`` simulations (see the module docstring)."""

    def __init__(self, domain: str, task: str, task_kwargs: dict[str, Any], contexts: Any, num_envs: int) -> None:
        self.domain, self.task_name, self.kwargs = domain, task, task_kwargs
        self.spec = suite.context_spec(domain, task)
        self.names = self.spec.names
        self.base = suite.check_context(domain, task, {}, task_kwargs)
        where = f"{domain}/{task}"
        self.sampler: ContextSampler | None = None
        if isinstance(contexts, ContextSampler):
            contexts.check(self.spec, f"{where} contexts")
            self.sampler = contexts
            self.generator = np.random.default_rng(contexts.seed)
            given = [self.base] * num_envs
        elif contexts is None:
            given = [self.base] * num_envs
        elif isinstance(contexts, Sequence) and not isinstance(contexts, str) and len(contexts) == num_envs:
            given = [
                suite.check_context(domain, task, c, task_kwargs, where=f"contexts[{i}]")
                for i, c in enumerate(contexts)
            ]
        else:
            raise ValueError(
                f"{where}: contexts must be a list of {num_envs} dicts (one per env) or a ContextSampler, "
                f"got {contexts!r}; valid keys: {self.spec.valid()}"
            )
        self.values = np.array([[c[n] for n in self.names] for c in given], np.float64).reshape(num_envs, -1)
        self.model_columns = [j for j, k in enumerate(self.spec.keys) if k.side == "model"]
        self.task_columns = [j for j, k in enumerate(self.spec.keys) if k.side == "task"]
        self.noisy = np.zeros(num_envs, bool)  # whose controls draw noise, under its context

    def bind(self, env: Any, batch: mujoco.batch.Batch, per_step: bool) -> None:
        """Ties the contexts to the vector env's scratch environment and batch; ``per_step``: the
        task's model changes every step (``model_for_step``)."""
        self.task, self.physics, self.batch, self.per_step = env.task, env.physics, batch, per_step
        self.fast = hasattr(self.task, "write_models")
        if per_step and not self.fast:
            raise ValueError(
                f"{self.domain}/{self.task_name} changes its model every step and cannot write the models of "
                "many contexts (no write_models): it takes no contexts in the vector env"
            )
        self.live: dict[str, np.ndarray] = {}
        self.rows: dict[tuple[float, ...], dict[str, np.ndarray]] = {}
        self.base_fields: dict[str, np.ndarray] | None = None

    def reseed(self, seed: int) -> None:
        """A sampler's generator starts again from its seed and ``seed`` (``reset(seed=...)``)."""
        if self.sampler is not None:
            self.generator = np.random.default_rng([self.sampler.seed, int(seed)])

    def start(self, ids: np.ndarray) -> None:
        """Envs ``ids`` start an episode: a sampler draws their contexts (in id order); their models follow."""
        if self.sampler is not None:
            for i in ids:
                drawn = self.sampler.sample(self.generator)
                values = suite.check_context(self.domain, self.task_name, drawn, self.kwargs, "sampled context")
                self.values[i] = [values[n] for n in self.names]
        if self.fast:
            self.write_models(ids, np.zeros(len(ids), np.int64))
        elif self.model_columns:
            for i in ids:
                self._copy_rows(int(i))

    def lend(self, i: int) -> None:
        """Gives the shared task env ``i``'s task keys, for its start draw and its noise flag."""
        for j in self.task_columns:
            setattr(self.task, self.names[j], float(self.values[i, j]))
        self.noisy[i] = bool(self.task.control_noise)

    def write_models(self, ids: np.ndarray, steps: np.ndarray) -> None:
        """The models of envs ``ids`` at their episodes' control steps ``steps`` (``write_models`` tasks)."""
        columns = {name: self.values[ids, j] for j, name in enumerate(self.names)}
        self.task.write_models(self.physics, self._field, ids, columns, steps)
        self.batch.set_const(ids)  # the derived fields, as mj_setConst gives the task's own model

    def task_arrays(self, ids: np.ndarray) -> dict[str, np.ndarray] | None:
        """Envs ``ids``' task keys, one array each (None when the task has none)."""
        if not self.task_columns:
            return None
        return {self.names[j]: self.values[ids, j] for j in self.task_columns}

    def info(self) -> dict[str, np.ndarray]:
        """Each key's value in every env: ``info["context"]``."""
        return {name: self.values[:, j].copy() for j, name in enumerate(self.names)}

    def _field(self, name: str) -> np.ndarray:
        """The batch's per-simulation values of model field ``name`` (expanded on first use)."""
        live = self.live.get(name)
        if live is None:
            live = self.live[name] = self.batch.expand(name)
        return live

    def _copy_rows(self, i: int) -> None:
        """Gives simulation ``i`` the model fields in which its context's model differs from the batch's."""
        if self.base_fields is None:
            model = self.batch.get_model(0)
            self.base_fields = {n: np.array(model_field(model, n)) for n in mujoco.batch.MODEL_FIELDS}
        rows = self._model_rows(tuple(self.values[i, self.model_columns]))
        for name in rows.keys() | self.live.keys():
            self._field(name)[i] = rows.get(name, self.base_fields[name])

    def _model_rows(self, key: tuple[float, ...]) -> dict[str, np.ndarray]:
        """The fields of the model the task builds with model values ``key`` that differ from the
        batch's (built once per distinct key; the task keys stay at their base values)."""
        rows = self.rows.get(key)
        if rows is not None:
            return rows
        values = {**self.base, **{self.names[j]: v for j, v in zip(self.model_columns, key)}}
        kwargs = suite.task_kwargs_with_context(self.domain, self.task_name, self.kwargs, values)
        model = suite.load(self.domain, self.task_name, task_kwargs=kwargs).physics.model.ptr
        assert self.base_fields is not None
        rows = {}
        for name, base in self.base_fields.items():
            value = np.asarray(model_field(model, name))
            if value.tobytes() != base.tobytes():
                rows[name] = value.copy()
        if len(self.rows) >= _CACHED_MODELS:
            self.rows.pop(next(iter(self.rows)))  # the oldest
        self.rows[key] = rows
        return rows


def model_field(model: Any, name: str) -> Any:
    """An ``MjModel`` field by its ``mujoco.batch.MODEL_FIELDS`` name (``"opt.timestep"`` included)."""
    owner, _, attribute = name.rpartition(".")
    return getattr(getattr(model, owner) if owner else model, attribute)


__all__ = ["ContextSampler", "SimContexts"]
