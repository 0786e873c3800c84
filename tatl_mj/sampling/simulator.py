"""A task's simulator: its environment, and for physics tasks a ``mujoco.batch.Batch``.

Every simulation of a Batch (MuJoCo's thread pool over many simulations of one
model) is one episode or query, and a control step of many is one C call of
``n_sub_steps`` ``mj_step``s with the control held constant, as dm_control does.
The paper state comes back through the domain contract (``states_from``), so
steps are bit-identical to stepping the dm_control environment.

Why ``mujoco.batch`` and not one ``mujoco.rollout`` call per control step: a
Batch row is the whole ``mjSTATE_INTEGRATION`` state, warm start included, so
an episode continues across calls exactly as one MjData would; ``rollout``
restarts ``qacc_warmstart`` from zero on every call, which moves contact
models (the bicycle) off the environment's numbers. ``tatl bench`` times raw
``mujoco.rollout`` as the physical limit.

Two more details make the replay exact. dm_control's legacy step (any
integrator but RK4) begins with ``mj_step2`` on the stages of the last forward
pass, which after a reset is ``Physics.after_reset``'s. The suite's domains
run a full forward there, so their first step is a plain step; a domain with
dm_control's own (actuation disabled) has the first step of each episode
replayed through its reset hooks (:meth:`Simulator.first_substep`). And a MuJoCo
warning during a step ends the episode with discount 0, reward 0 and the last
finite state, as ``common.Environment`` does.

Tasks whose model changes during an episode (``rollout_compatible = False``,
the time-varying pendulum) are stepped through their environment; where the
model depends on the step alone (``model_for_step``), their one-step queries
(each an episode's first step) and evaluation episodes are batched on the model
of the step. A task with a known tabular model steps its :class:`Table`. Every MuJoCo substep taken is
counted (:func:`physics_substeps`).
"""

from __future__ import annotations

import collections
import contextlib
import contextvars
import functools
import weakref
from typing import Any, Callable, Iterator

import dm_env
import mujoco
import mujoco.batch
import numpy as np
from dm_control.rl import control

from tatl_mj import suite
from tatl_mj.description import CellMap
from tatl_mj.suite.common import StatePhysics
from tatl_mj.validation import integer, is_integer

_INTEGRATION = mujoco.mjtState.mjSTATE_INTEGRATION.value
_WARNING_NUMBER = 1  # Batch.warning is (nsim, mjNWARNING, [lastinfo, number])
_SMALL_QUERY = 16  # step_from queries of fewer states are stepped on one thread

# MuJoCo threads of the batched calls not given n_threads: mujoco_threads() sets it.
_THREADS: contextvars.ContextVar[int] = contextvars.ContextVar("tatl_mj_mujoco_threads", default=2)

# MuJoCo substeps this process has taken, by "domain/task": what a run's work is
# measured against (raw mujoco.rollout speed over the same substeps).
SUBSTEPS: collections.Counter = collections.Counter()


def physics_substeps() -> dict[str, int]:
    """MuJoCo substeps this process has taken so far, by ``"domain/task"`` (tasks with physics)."""
    return dict(SUBSTEPS)


def _kwargs_key(task_kwargs: dict[str, Any] | None) -> tuple[tuple[str, Any], ...]:
    kwargs = dict(task_kwargs or {})
    if "random" in kwargs:
        raise ValueError("task_kwargs must not contain 'random'; pass seed instead")
    return tuple(sorted(kwargs.items()))


class Simulator:
    """A task's environment, and for physics tasks the Batch that steps its model."""

    def __init__(self, domain: str, task: str, kwargs: tuple[tuple[str, Any], ...], n_threads: int):
        self.domain, self.task_name, self.kwargs = domain, task, dict(kwargs)
        self.n_threads = n_threads
        self.env = self.make_env(0)
        self.actions = np.asarray(suite.action_set(domain))
        self.action_dim = 1 if self.actions.ndim == 1 else self.actions.shape[1]
        physics = getattr(self.env, "physics", None)
        self.fast = physics is not None and bool(getattr(self.env.task, "rollout_compatible", False))
        # Where the model depends on the step alone (model_for_step), one-step queries, each
        # an episode's first step, and lockstep evaluation episodes are batched too.
        self.batched_queries = self.fast or (physics is not None and hasattr(self.env.task, "model_for_step"))
        self.key = f"{domain}/{task}"
        # MuJoCo substeps per control step (0 without physics: nothing to count).
        self.substeps = 0 if physics is None else int(round(self.env.control_timestep() / physics.timestep()))
        self.table: Table | None = None
        # Lockstep evaluation episodes share one model a step, edited in this environment's physics.
        self.step_env: dm_env.Environment | None = None
        if not self.batched_queries:
            known_model = suite.describe(domain, task, self.kwargs).known_model
            if known_model is not None and np.array_equal(self.actions, np.arange(len(self.actions))):
                self.table = Table(known_model, self.time_limit())
            return
        if not self.fast:
            # A reset environment of its own, on the model of an episode's first step and
            # never stepped, answers the queries while the stepped environment's moves on.
            query_env = self.make_env(0)
            query_env.reset()
            query_env.task.model_for_step(query_env.physics, 0)
            physics = query_env.physics
            self.step_env = self.make_env(0)
        self.physics = physics
        self.model = physics.model.ptr
        self.n_sub = int(round(self.env.control_timestep() / physics.timestep()))
        # The state a freshly reset MjData has (time 0, no warm start); step_from
        # writes qpos and qvel into it, as set_state_vector does.
        data = mujoco.MjData(self.model)
        self.blank_row = np.empty(mujoco.mj_stateSize(self.model, _INTEGRATION))
        mujoco.mj_getState(self.model, data, self.blank_row, _INTEGRATION)
        self._batch: mujoco.batch.Batch | None = None
        self._small_batch: mujoco.batch.Batch | None = None
        # Live views of each batch's fields: Batch.bind builds one per call (~15 us,
        # five a query or a collection's pass, as much as a small batch's physics).
        self.views: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
        self._spare_env: dm_env.Environment | None = None
        # How long random-action episodes of this task lasted, by step limit: the
        # ended-length histogram of every random collection so far, from which the
        # next one starts its schedule and call lengths (speed only; see collect()).
        self.random_lengths: dict[float, np.ndarray] = {}
        # dm_control's legacy step (every integrator but RK4) starts a step with
        # mj_step2 on the stages of the last forward pass; after a reset that is
        # Physics.after_reset's. dm_control's own runs with actuation disabled, which
        # leaves actuator_velocity at zero: such a domain's first step of an episode is
        # replayed through its reset hooks (see first_substep). StatePhysics's is a
        # full forward at the reset state, whose position and velocity stages (all
        # that mj_step2 keeps; they do not depend on the controls) are those a plain
        # mj_step computes there: its first step is a plain step (tested).
        self.legacy_first = (
            bool(getattr(physics, "legacy_step", True))
            and self.model.opt.integrator != mujoco.mjtIntegrator.mjINT_RK4
            and type(physics).after_reset is not StatePhysics.after_reset
        )

    def make_env(self, random: Any) -> dm_env.Environment:
        return suite.load(self.domain, self.task_name, task_kwargs={**self.kwargs, "random": random})

    @contextlib.contextmanager
    def seeded_env(self, seed: int) -> Any:
        """What ``make_env(seed)`` gives, for collect() and evaluate() to draw from.

        Building an environment (dm_control's Physics and its indexers) costs
        as much as collecting many transitions; one is kept and its task's
        random stream reseeded in place, which is what a new
        ``RandomState(seed)`` is. A nested use (a policy that collects) gets a new one.
        """
        env, self._spare_env = self._spare_env, None
        if env is None or not is_integer(seed):
            env = self.make_env(seed)
        else:
            env.task.random.seed(seed)
        try:
            yield env
        finally:
            self._spare_env = env

    def scheduled_models(self, batch: mujoco.batch.Batch) -> Callable[[int], None]:
        """``model_for(step)``: gives ``batch`` the model of control step ``step`` of an
        episode (a task whose model depends on the step alone, ``model_for_step``),
        edited in the stepped environment's physics."""
        task, physics = self.env.task, self.step_env.physics  # type: ignore[union-attr]

        def model_for(step: int) -> None:
            task.model_for_step(physics, step)
            batch.set_models(physics.model.ptr)  # read again after every edit

        return model_for

    def new_batch(self, nsim: int) -> mujoco.batch.Batch:
        """A Batch of ``nsim`` simulations of the task's model (slow to make: made once a call)."""
        return mujoco.batch.Batch(self.model, nsim=max(nsim, 1), nthread=self.n_threads)

    def query_batch(self, nsim: int) -> mujoco.batch.Batch:
        """The cached Batch for one-step queries, grown to at least ``nsim`` simulations.

        collect() and evaluate() make their own, so that a policy may query
        step_from() while they run. A query of fewer than ``_SMALL_QUERY`` states
        runs on one thread: handing a few simulations to the thread pool and
        waiting for them costs more than their physics. Each simulation steps
        alone either way, so the numbers are the same.
        """
        if nsim < _SMALL_QUERY:
            if self._small_batch is None:
                self._small_batch = mujoco.batch.Batch(self.model, nsim=_SMALL_QUERY - 1, nthread=1)
            return self._small_batch
        if self._batch is None or self._batch.nsim < nsim:
            self._batch = self.new_batch(nsim)
        return self._batch

    def time_limit(self) -> Any:
        """The task's ``time_limit`` argument: as given, else its factory's default."""
        return suite.time_limit(self.domain, self.task_name, self.kwargs)

    def step_limit(self, max_episode_steps: int | None) -> float:
        """Steps after which an episode ends by time limit, as dm_control counts them.

        Physics tasks only; environment loops keep their environment's own limit.
        """
        if max_episode_steps is not None:
            return float(max_episode_steps)
        # dm_control's own float expression, so that the count matches exactly.
        return self.time_limit() / (self.physics.timestep() * self.n_sub)

    def bound(self, batch: mujoco.batch.Batch, name: str) -> np.ndarray:
        """``batch.bind(name)``, made once per batch (the per-step hot path)."""
        views = self.views.setdefault(batch, {})
        if name not in views:
            views[name] = batch.bind(name)
        return views[name]

    def place(self, batch: mujoco.batch.Batch, ids: np.ndarray, qpos: np.ndarray, qvel: np.ndarray) -> None:
        """Puts simulations ``ids`` at a fresh reset's state with these qpos and qvel.

        ctrl is left as reset leaves it: ``advance`` writes it before every step.
        """
        batch.state[ids] = self.blank_row
        self.bound(batch, "qpos")[ids] = qpos
        self.bound(batch, "qvel")[ids] = qvel

    def start_episodes(self, batch: mujoco.batch.Batch, ids: np.ndarray, env: Any) -> np.ndarray:
        """Puts simulations ``ids`` at the starts of ``env``'s next ``len(ids)`` episodes.

        One call of the task's ``start_configurations`` draws what as many
        successive resets of ``env`` would. Returns their paper states.
        """
        qpos, qvel = env.task.start_configurations(env.physics, len(ids))
        self.place(batch, ids, qpos, qvel)
        return self.physics.states_from(qpos, qvel)

    def advance(
        self,
        batch: mujoco.batch.Batch,
        ids: np.ndarray,
        controls: np.ndarray,
        first: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """One control step of simulations ``ids`` (sorted): (next paper states, diverged).

        ``first`` marks the simulations whose episode (or query) starts with
        this step, right after a reset.
        """
        self.bound(batch, "ctrl")[ids] = controls
        SUBSTEPS[self.key] += len(ids) * self.n_sub
        _clear_warnings(batch, ids)
        diverged = np.zeros(len(ids), bool)
        if self.legacy_first and first.any():
            for k in np.flatnonzero(first):
                diverged[k] = self.first_substep(batch.state[ids[k]])
            if self.n_sub > 1:
                batch.step(ids[first], nstep=self.n_sub - 1)
            ids_rest = ids[~first]
            if len(ids_rest):
                batch.step(ids_rest, nstep=self.n_sub)
        else:
            batch.step(ids, nstep=self.n_sub)
        # Any MuJoCo warning is a PhysicsError in dm_control.
        diverged |= _warned(batch, ids)
        states = self.physics.states_from(self.bound(batch, "qpos")[ids], self.bound(batch, "qvel")[ids])
        return states, diverged

    def advance_steps(self, batch: mujoco.batch.Batch, ids: np.ndarray, controls: np.ndarray) -> np.ndarray | None:
        """``len(controls)`` control steps of simulations ``ids`` in one C call.

        ``controls`` is (K, len(ids), nu); with ``legacy_first``, none of the
        steps may be an episode's first (see :meth:`advance`).
        Returns the next paper states after each step (K, len(ids), d); or None,
        with the simulations put back where they were, when MuJoCo warned (the
        caller then steps once, where a diverged step is handled).
        Bit-identical to K calls of ``advance``.
        """
        k, n = controls.shape[:2]
        SUBSTEPS[self.key] += k * n * self.n_sub
        rows = batch.state[ids].copy()
        _clear_warnings(batch, ids)
        # The control of a control step is held over its n_sub substeps, as dm_control does.
        per_substep = np.repeat(controls.transpose(1, 0, 2), self.n_sub, axis=1)
        record = batch.rollout(k * self.n_sub, control=per_substep, record=("qpos", "qvel"), ids=ids)
        if _warned(batch, ids).any():
            batch.state[ids] = rows
            return None
        ends = slice(self.n_sub - 1, None, self.n_sub)  # the last substep of each control step

        def step_major(field: str) -> np.ndarray:
            values = record[field][:, ends]
            return values.transpose(1, 0, 2).reshape(k * n, -1)

        states = self.physics.states_from(step_major("qpos"), step_major("qvel"))
        return states.reshape(k, n, -1)

    def first_substep(self, row: np.ndarray) -> bool:
        """dm_control's first substep after a reset, on one state row in place.

        Returns whether MuJoCo warned (the step diverged).
        """
        physics = self.physics
        try:
            with physics.reset_context():
                mujoco.mj_setState(self.model, physics.data.ptr, row, _INTEGRATION)
        except control.PhysicsError:
            return True
        mujoco.mj_step2(self.model, physics.data.ptr)
        mujoco.mj_getState(self.model, physics.data.ptr, row, _INTEGRATION)
        # The counts as one array (iterating the warning structs costs ~0.3 ms).
        return bool(physics.data.ptr.warning.number.any())


class Table:
    """A task's known exact model, which its environment's steps follow.

    The contract (the grid world's): from cell c, action index a leads to cell
    ``next_state[c, a]`` with ``reward[c, a]``; the episode ends there with
    discount 0 where ``absorbing[c, a]``, else by time limit after
    ``time_limit`` steps. The environment loops step this table instead of the
    environment, whose Python step costs more than the lookup (resets, and the
    random draws they make, still go through the environment).
    """

    def __init__(self, known_model: Any, time_limit: int):
        next_state, reward, absorbing, cells = known_model()
        self.cell_map = CellMap(cells)
        self.states = self.cell_map.cells.astype(np.float64)
        self.next_state = np.asarray(next_state, np.int64)
        self.reward = np.asarray(reward, np.float64)
        self.absorbing = np.asarray(absorbing, bool)
        self.time_limit = int(time_limit)
        # As lists for the per-step loops: indexing numpy arrays with scalars costs more.
        self.next_list, self.reward_list = self.next_state.tolist(), self.reward.tolist()
        self.absorbing_list = self.absorbing.tolist()

    def episode_limit(self, max_episode_steps: int | None) -> int:
        """Steps after which an episode ends if nothing ends it sooner."""
        return self.time_limit if max_episode_steps is None else min(self.time_limit, max_episode_steps)

    def cell(self, timestep: dm_env.TimeStep) -> int:
        return int(self.cell_map.index(observed_state(timestep)[None])[0])


def controls_each(
    task: Any, values: np.ndarray, randoms: list | None, context: dict[str, np.ndarray] | None = None
) -> np.ndarray:
    """The control rows of action values ``values`` (N, m): row i draws the noise its controls
    carry from ``randoms[i]``, the same numbers as ``task.controls(values[i:i + 1], randoms[i])``;
    ``randoms`` None: noise-free controls, which draw nothing (one call for all rows).
    ``context``: per-row task settings (a vector env's contexts), for a task whose
    ``controls_each`` takes them."""
    if randoms is None:
        return task.controls(values, None)
    each = getattr(task, "controls_each", None)  # optional in the domain contract: all rows in one call
    if each is not None:
        return each(values, randoms) if context is None else each(values, randoms, context=context)
    return np.concatenate([task.controls(values[j : j + 1], r) for j, r in enumerate(randoms)])


def _clear_warnings(batch: mujoco.batch.Batch, ids: np.ndarray) -> None:
    """Zeroes simulations ``ids``' MuJoCo warning counts before a call.

    A count does not only grow: MuJoCo's checks for bad positions, velocities and
    accelerations reset the data, counts included, and then count one. A simulation
    that warned once (an earlier episode or query in its slot) would show the same 1
    after warning again, so counts are cleared and any count after the call is new.
    Only ``ids`` are touched: a query batch grown once to thousands of simulations is
    stepped ten at a time.
    """
    batch.warning[ids] = 0


def _warned(batch: mujoco.batch.Batch, ids: np.ndarray) -> np.ndarray:
    """Whether simulations ``ids`` warned since :func:`_clear_warnings`."""
    return batch.warning[ids, :, _WARNING_NUMBER].any(axis=1)


@functools.lru_cache(maxsize=16)
def _cached(domain: str, task: str, kwargs: tuple[tuple[str, Any], ...], n_threads: int) -> Simulator:
    return Simulator(domain, task, kwargs, n_threads)


@contextlib.contextmanager
def mujoco_threads(n: int) -> Iterator[None]:
    """Within it, batched calls not given ``n_threads`` step on ``n`` MuJoCo threads (default 2).

    Each simulation steps alone whatever the count, so the numbers are the same; a
    run's units, each on one core, take 1, as two pools of two threads on two cores
    wait on each other.
    """
    token = _THREADS.set(integer("", "n_threads", n, 1))
    try:
        yield
    finally:
        _THREADS.reset(token)


def simulator_for(domain: str, task: str, task_kwargs: dict[str, Any] | None, n_threads: int | None) -> Simulator:
    """The (cached) simulator of ``domain/task``; ``n_threads`` None: :func:`mujoco_threads`'s."""
    n_threads = _THREADS.get() if n_threads is None else integer("", "n_threads", n_threads, 1)
    key = _kwargs_key(task_kwargs)
    try:
        hash(key)
    except TypeError:  # unhashable task kwargs: build without caching
        return Simulator(domain, task, key, n_threads)
    return _cached(domain, task, key, n_threads)


def episode_simulator(
    domain: str, task: str, task_kwargs: dict[str, Any] | None, n_threads: int | None, max_episode_steps: int | None
) -> Simulator:
    """:func:`simulator_for`, for episodes that end after ``max_episode_steps`` (checked; None: the task's limit)."""
    if max_episode_steps is not None:
        integer("", "max_episode_steps", max_episode_steps, 1)
    return simulator_for(domain, task, task_kwargs, n_threads)


def is_batched(domain: str, task: str, task_kwargs: dict[str, Any] | None = None) -> bool:
    """Whether ``domain/task`` runs on the batched MuJoCo path (else an environment loop)."""
    return simulator_for(domain, task, task_kwargs, 1).fast


def observed_state(timestep: dm_env.TimeStep) -> np.ndarray:
    obs = timestep.observation
    return np.asarray(obs["state"] if isinstance(obs, dict) else obs, np.float64)
