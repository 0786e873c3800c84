"""Batched transitions at MuJoCo's speed: many episodes stepped in lockstep in C threads.

Learners eat batches of transitions; a Python loop over ``env.step`` spends most
of its time outside the physics. Here every parallel episode is one row of a
``mujoco.batch.Batch`` (MuJoCo's thread pool over many simulations of one
model), and a control step of all live episodes is one C call of
``n_sub_steps`` ``mj_step``s with the control held constant, as dm_control
does. Task logic runs vectorised through the domain contract
(``states_from``, ``batch_reward``, ``batch_absorbing``, ``controls``), so the
transitions are bit-identical to stepping the dm_control environment.

Why ``mujoco.batch`` and not one ``mujoco.rollout`` call per control step: a
Batch row is the whole ``mjSTATE_INTEGRATION`` state, warm start included, so
an episode continues across calls exactly as one MjData would; ``rollout``
restarts ``qacc_warmstart`` from zero on every call, which moves contact
models (the bicycle) by ~1e-12 per step. Both run at the same speed; ``tatl
bench`` times raw ``mujoco.rollout`` as the physical limit.

Two more details make the replay exact. dm_control's legacy step (any
integrator but RK4) begins with ``mj_step2`` on the stages of the last forward
pass, which after a reset is ``Physics.after_reset``'s (run with actuation
disabled by default); the first step of each episode is replayed through the
domain's own reset hooks. And a MuJoCo warning during a step ends the episode
with discount 0, reward 0 and the last finite state, as ``common.Environment``
does.

``collect`` returns the first ``n_transitions`` of the episodes in start
order, so the data are what a sequential loop would collect; it starts
episodes only as fast as they are expected to be needed, so that long
(time-limited) episodes are not cut short and thrown away. With random
actions, each episode draws its actions, and the noise its controls carry,
from its own blocks of random numbers (:class:`_EpisodeDraws`), so the data
depend on the seed alone; the live episodes then take several control steps
in one ``Batch.rollout`` call, and an episode that ends in it idles to the
call's end (how many steps a call takes is a speed choice, :func:`_call_length`).

Tasks whose model changes during an episode (``rollout_compatible = False``,
the time-varying pendulum) and tasks without physics (a known tabular model) are
stepped through their environments behind the same functions.

Seeding: ``collect``/``evaluate`` with ``seed`` draw start states from the
successive resets of the task created with ``task_kwargs["random"] = seed``.
``collect``'s random actions and their controls' noise are each episode's own
draws from ``np.random.default_rng(seed)`` and generators derived from it;
so is ``evaluate``'s controls' noise (:func:`_evaluation_randoms`). In
``collect`` with a policy, the task's ``random`` feeds ``Task.controls`` (rider
noise) in lockstep order. Without control noise, a collection is exactly a
plain loop over that environment with its actions.
"""

from __future__ import annotations

import collections
import contextlib
import functools
import inspect
import time
import weakref
from typing import Any, Callable

import dm_env
import mujoco
import mujoco.batch
import numpy as np
from dm_control.rl import control

from tatl_mj import suite
from tatl_mj.description import CellMap
from tatl_mj.transitions import Transitions
from tatl_mj.validation import integer, is_integer

IndexPolicy = Callable[[np.ndarray], np.ndarray]
"""``policy(states (N, d)) -> (N,)`` indices into the domain's ``ACTIONS``."""

ValuePolicy = Callable[[np.ndarray], np.ndarray]
"""``policy(states (N, d)) -> (N, action_dim)`` action values in actuator units."""

DEFAULT_PARALLEL = 256  # most episodes collect() steps together with a policy
_MOST_PARALLEL = 2048  # ... and with random actions, for the largest collections
_TRANSITIONS_PER_SLOT = 64  # random actions: a parallel episode per this many transitions asked for
_MIN_LIVE = 8  # fewest, while more may be needed (a constant: results must not depend on threads)
_MOST_STEPS = 64  # most control steps collect() takes in one call
_BLOCK = 256  # control steps of an episode's random actions drawn at a time (>= _MOST_STEPS)
_INTEGRATION = mujoco.mjtState.mjSTATE_INTEGRATION.value
_WARNING_NUMBER = 1  # Batch.warning is (nsim, mjNWARNING, [lastinfo, number])
_SMALL_QUERY = 16  # step_from queries of fewer states are stepped on one thread

# MuJoCo substeps this process has taken, by "domain/task": what a run's work is
# measured against (raw mujoco.rollout speed over the same substeps).
_SUBSTEPS: collections.Counter = collections.Counter()


def physics_substeps() -> dict[str, int]:
    """MuJoCo substeps this process has taken so far, by ``"domain/task"`` (tasks with physics)."""
    return dict(_SUBSTEPS)


# --- Simulators ------------------------------------------------------------------


def _kwargs_key(task_kwargs: dict[str, Any] | None) -> tuple[tuple[str, Any], ...]:
    kwargs = dict(task_kwargs or {})
    if "random" in kwargs:
        raise ValueError("task_kwargs must not contain 'random'; pass seed instead")
    return tuple(sorted(kwargs.items()))


class _Simulator:
    """A task's environment, and for physics tasks the Batch that steps its model."""

    def __init__(self, domain: str, task: str, kwargs: tuple[tuple[str, Any], ...], n_threads: int):
        self.domain, self.task_name, self.kwargs = domain, task, dict(kwargs)
        self.n_threads = n_threads
        self.env = self.make_env(0)
        self.actions = np.asarray(suite.action_set(domain))
        self.action_dim = 1 if self.actions.ndim == 1 else self.actions.shape[1]
        physics = getattr(self.env, "physics", None)
        self.fast = physics is not None and bool(getattr(self.env.task, "rollout_compatible", False))
        self.key = f"{domain}/{task}"
        # MuJoCo substeps per control step (0 without physics: nothing to count).
        self.substeps = 0 if physics is None else int(round(self.env.control_timestep() / physics.timestep()))
        self.table: _Table | None = None
        if not self.fast:
            known_model = suite.describe(domain, task, self.kwargs).known_model
            if known_model is not None and np.array_equal(self.actions, np.arange(len(self.actions))):
                self.table = _Table(known_model, self.time_limit())
            return
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
        self._views: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
        self._spare_env: dm_env.Environment | None = None
        # How long random-action episodes of this task lasted, by step limit: the
        # ended-length histogram of every random collection so far, from which the
        # next one starts its schedule and call lengths (speed only; see collect()).
        self.random_lengths: dict[float, np.ndarray] = {}
        # dm_control's legacy step (every integrator but RK4) starts a step with
        # mj_step2 on the stages of the last forward pass; after a reset that is
        # Physics.after_reset's (by default run with actuation disabled, which
        # leaves actuator_velocity at zero). The first step of an episode is
        # replayed through the domain's own reset hooks (see _first_substep).
        self.legacy_first = bool(getattr(physics, "legacy_step", True)) and (
            self.model.opt.integrator != mujoco.mjtIntegrator.mjINT_RK4
        )

    def make_env(self, random: Any) -> dm_env.Environment:
        return suite.load(self.domain, self.task_name, task_kwargs={**self.kwargs, "random": random})

    @contextlib.contextmanager
    def seeded_env(self, seed: int) -> Any:
        """What ``make_env(seed)`` gives, for collect() and evaluate() to draw from.

        Building an environment costs ~20 ms (dm_control's Physics and its
        indexers), as much as collecting 1,000 cart-pole transitions; one is kept
        and its task's random stream reseeded in place, which is what a new
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

    def new_batch(self, nsim: int) -> mujoco.batch.Batch:
        """A Batch of ``nsim`` simulations of the task's model (about 2 ms to make)."""
        return mujoco.batch.Batch(self.model, nsim=max(nsim, 1), nthread=self.n_threads)

    def query_batch(self, nsim: int) -> mujoco.batch.Batch:
        """The cached Batch for one-step queries, grown to at least ``nsim`` simulations.

        collect() and evaluate() make their own, so that a policy may query
        step_from() while they run. A query of fewer than ``_SMALL_QUERY`` states
        runs on one thread: handing a few simulations to the thread pool and
        waiting for them costs more than their physics (a horizon controller's
        5-state cart-pole queries took twice the time on two threads). Each
        simulation steps alone either way, so the numbers are the same.
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
        time_limit = self.kwargs.get("time_limit")
        if time_limit is None:
            factory = suite.domain(self.domain).TASKS[self.task_name]
            time_limit = inspect.signature(factory).parameters["time_limit"].default
        return time_limit

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
        views = self._views.setdefault(batch, {})
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
        _SUBSTEPS[self.key] += len(ids) * self.n_sub
        before = _warning_totals(batch, ids)
        diverged = np.zeros(len(ids), bool)
        if self.legacy_first and first.any():
            for k in np.flatnonzero(first):
                diverged[k] = self._first_substep(batch.state[ids[k]])
            if self.n_sub > 1:
                batch.step(ids[first], nstep=self.n_sub - 1)
            ids_rest = ids[~first]
            if len(ids_rest):
                batch.step(ids_rest, nstep=self.n_sub)
        else:
            batch.step(ids, nstep=self.n_sub)
        # Any new MuJoCo warning is a PhysicsError in dm_control.
        diverged |= _warning_totals(batch, ids) != before
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
        _SUBSTEPS[self.key] += k * n * self.n_sub
        before, rows = _warning_totals(batch, ids), batch.state[ids].copy()
        # The control of a control step is held over its n_sub substeps, as dm_control does.
        per_substep = np.repeat(controls.transpose(1, 0, 2), self.n_sub, axis=1)
        record = batch.rollout(k * self.n_sub, control=per_substep, record=("qpos", "qvel"), ids=ids)
        if (_warning_totals(batch, ids) != before).any():
            batch.state[ids] = rows
            return None
        ends = slice(self.n_sub - 1, None, self.n_sub)  # the last substep of each control step

        def step_major(field: str) -> np.ndarray:
            values = record[field][:, ends]
            return values.transpose(1, 0, 2).reshape(k * n, -1)

        states = self.physics.states_from(step_major("qpos"), step_major("qvel"))
        return states.reshape(k, n, -1)

    def _first_substep(self, row: np.ndarray) -> bool:
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


class _Table:
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
        return int(self.cell_map.index(_observed_state(timestep)[None])[0])


def _warning_totals(batch: mujoco.batch.Batch, ids: np.ndarray) -> np.ndarray:
    """Simulations ``ids``' counts of MuJoCo warnings so far: counts only grow, so a new
    one (a PhysicsError in dm_control) changes the total. Only ``ids`` are read: a
    query batch grown once to thousands of simulations is stepped ten at a time."""
    return batch.warning[ids, :, _WARNING_NUMBER].sum(axis=1)


@functools.lru_cache(maxsize=16)
def _cached(domain: str, task: str, kwargs: tuple[tuple[str, Any], ...], n_threads: int) -> _Simulator:
    return _Simulator(domain, task, kwargs, n_threads)


def _simulator(domain: str, task: str, task_kwargs: dict[str, Any] | None, n_threads: int) -> _Simulator:
    n_threads = integer("", "n_threads", n_threads, 1)
    key = _kwargs_key(task_kwargs)
    try:
        hash(key)
    except TypeError:  # unhashable task kwargs: build without caching
        return _Simulator(domain, task, key, n_threads)
    return _cached(domain, task, key, n_threads)


def is_batched(domain: str, task: str, task_kwargs: dict[str, Any] | None = None) -> bool:
    """Whether ``domain/task`` runs on the batched MuJoCo path (else an environment loop)."""
    return _simulator(domain, task, task_kwargs, 1).fast


# --- Argument checks -----------------------------------------------------------


def _check_indices(indices: Any, n: int, n_actions: int) -> np.ndarray:
    a = np.asarray(indices)
    if a.shape != (n,) or a.dtype.kind not in "iu":  # signed or unsigned integers
        raise ValueError(f"policy must return ({n},) integer action indices, got {a.dtype} {a.shape}")
    # One state a call in the environment loops: a scalar comparison, not two reductions.
    low, high = (a[0], a[0]) if n == 1 else (a.min(), a.max()) if n else (0, 0)
    if low < 0 or high >= n_actions:
        raise ValueError(f"action indices must be in 0..{n_actions - 1}, got {low}..{high}")
    return a.astype(np.int64, copy=False)


def _check_values(values: Any, n: int, sim: _Simulator) -> np.ndarray:
    v = np.asarray(values, np.float64)
    if v.shape == (n,) and sim.action_dim == 1:
        v = v[:, None]
    if v.shape != (n, sim.action_dim):
        if np.issubdtype(sim.actions.dtype, np.integer):  # the task takes action indices
            raise ValueError(
                f"policy must return ({n},) action indices in 0..{len(sim.actions) - 1} "
                f"for {sim.domain}, got shape {v.shape}"
            )
        raise ValueError(f"policy must return ({n}, {sim.action_dim}) action values, got {v.shape}")
    return v


def _observed_state(timestep: dm_env.TimeStep) -> np.ndarray:
    obs = timestep.observation
    return np.asarray(obs["state"] if isinstance(obs, dict) else obs, np.float64)


# --- Collection ------------------------------------------------------------------


class _Episodes:
    """Lengths of started episodes, which ones the first n transitions still need, and
    how many ended after each number of steps."""

    def __init__(self, n: int, ended_before: np.ndarray | None = None):
        self.n = n
        self.lengths = np.zeros(64, np.int64)
        self.count = 0
        # ended[k]: episodes that ended after k steps (the schedule's survival data;
        # a histogram, since sorting every ended length each pass cost as much as the step),
        # from ``ended_before`` on: those of earlier collections of the same episodes.
        self.ended = np.zeros(64, np.int64) if ended_before is None else ended_before.copy()

    def start(self, k: int) -> np.ndarray:
        """The numbers of ``k`` new episodes."""
        while self.count + k > len(self.lengths):
            self.lengths = np.concatenate([self.lengths, np.zeros_like(self.lengths)])
        self.count += k
        return np.arange(self.count - k, self.count)

    def end(self, episodes: np.ndarray) -> None:
        if len(episodes) == 0:
            return
        counts = np.bincount(self.lengths[episodes], minlength=len(self.ended))
        if len(counts) > len(self.ended):
            self.ended = np.concatenate([self.ended, np.zeros(len(counts) - len(self.ended), np.int64)])
        self.ended += counts

    def total(self) -> int:
        return int(self.lengths[: self.count].sum())

    def covered(self, episodes: np.ndarray) -> np.ndarray:
        """True where episodes 0..e already hold n transitions, so e need not go on.

        Lengths only grow, so once true it stays true, and the first n
        transitions in episode order never need a step beyond it.
        """
        return np.cumsum(self.lengths[: self.count])[episodes] >= self.n


def _survival(ended: np.ndarray, ages: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Kaplan-Meier estimate of P(length > t) at each of ``times`` (increasing step
    counts that include every length in ``ended`` up to the last of them).

    ``ended``, ``ages``: as :func:`_expected_remaining` takes them. At t, the episodes
    at risk are those that ended after t steps or more and those running at age t or more.
    """
    inside = times < len(ended)
    at = np.minimum(times, len(ended) - 1)
    deaths = np.where(inside, ended[at], 0)
    ended_since = np.cumsum(ended[::-1])[::-1]  # episodes that ended after t steps or more
    at_risk = np.where(inside, ended_since[at], 0) + (len(ages) - np.searchsorted(np.sort(ages), times, side="left"))
    return np.cumprod(1.0 - deaths / np.maximum(at_risk, 1.0))


def _expected_remaining(ended: np.ndarray, ages: np.ndarray, limit: float) -> tuple[float, np.ndarray]:
    """(expected length of a new episode, expected further steps of each running one).

    ``ended[k]``: how many episodes ended after k steps; ``ages``: steps taken so
    far by the running ones (censored lengths). The survival curve is the Kaplan-Meier
    estimate; the mean of the ended lengths alone runs short, since the short
    episodes end first (starting episodes by it stepped up to 50% more than n).
    Beyond the longest length seen, survivors are assumed to go on to twice it
    (capped by the limit). Before any episode ends: the limit, or 100 steps.
    """
    steps = np.flatnonzero(ended)
    if len(steps) == 0:
        cap = limit if np.isfinite(limit) else 100.0
        return cap, np.maximum(cap - ages, 1.0)
    survival = np.concatenate([[1.0], _survival(ended, ages, steps)])  # on [edges[i], edges[i+1])
    ages = ages.astype(np.float64)
    longest = float(max(steps[-1], ages.max() if len(ages) else 0.0))
    tail_end = max(min(2.0 * longest, limit), longest)
    edges = np.concatenate([[0.0], steps, [tail_end]])
    area = np.concatenate([[0.0], np.cumsum(survival * np.diff(edges))])  # integral of S up to edges[i]
    k = np.searchsorted(edges, ages, side="right") - 1
    area_to_age = area[k] + survival[k] * (ages - edges[k])
    residual = (area[-1] - area_to_age) / np.maximum(survival[k], 1e-12)
    return float(area[-1]), np.maximum(residual, 1.0)


def collect(
    domain: str,
    task: str,
    n_transitions: int,
    seed: int,
    policy: IndexPolicy | None = None,
    task_kwargs: dict[str, Any] | None = None,
    max_episode_steps: int | None = None,
    n_threads: int = 2,
    n_parallel: int | None = None,
) -> Transitions:
    """Exactly ``n_transitions`` transitions of whole episodes, in episode order.

    Episodes start from the task's own start distribution (successive resets of
    the task seeded with ``seed``) and take actions uniform over ``ACTIONS``
    indices, or ``policy(states)`` evaluated for all live episodes at once. An
    episode ends at an absorbing state or after ``max_episode_steps`` (default:
    the task's time limit), which is not absorbing. Up to ``n_parallel``
    episodes run in lockstep; by default (None) ``DEFAULT_PARALLEL`` with a
    policy, and with random actions one per 64 transitions asked for, from 256
    to 2048 (:func:`_parallel`).

    Random actions, and the noise the task's controls draw with them (the
    bicycle's rider), are each episode's own (:class:`_EpisodeDraws`): the
    transitions depend on ``seed`` alone, not on ``n_parallel`` or ``n_threads``.
    With a policy, the controls' noise comes from the task's random stream in
    lockstep order, so the transitions also depend on ``n_parallel``.

    How many episodes to start and how many steps a call takes come from the
    lengths of the episodes so far; random collections of a task also count
    the episodes of its earlier random collections in this process (bicycle,
    1.5x10^4 transitions: 13% of stepped substeps idle cold, 8% warm).
    Neither changes the data.
    """
    n = integer("", "n_transitions", n_transitions, 1)
    n_parallel = _parallel(n, policy) if n_parallel is None else integer("", "n_parallel", n_parallel, 1)
    if max_episode_steps is not None:
        integer("", "max_episode_steps", max_episode_steps, 1)
    sim = _simulator(domain, task, task_kwargs, n_threads)
    if sim.table is not None:
        return _collect_table(sim, n, seed, policy, max_episode_steps)
    if not sim.fast:
        return _collect_env(sim, n, seed, policy, max_episode_steps)
    limit = sim.step_limit(max_episode_steps)
    # Random episodes of a task last as long in every collection: each one starts its
    # estimates of their lengths from all the earlier ones (a speed choice only).
    earlier = sim.random_lengths.get(limit) if policy is None else None
    with sim.seeded_env(seed) as env:
        collection = _Collection(sim, env, n, n_parallel, limit, earlier)
        transitions = collection.run(seed, policy)
    if policy is None:
        sim.random_lengths[limit] = collection.episodes.ended
    return transitions


def _parallel(n: int, policy: IndexPolicy | None) -> int:
    """collect()'s default ``n_parallel`` for ``n`` transitions (a speed choice).

    With random actions the data do not depend on it, and more simulations a
    call spread the Python around each call over more steps, so that calls can
    be shorter and fewer steps idle after an episode's end (cart-pole, 6x10^4
    transitions: 9% of stepped substeps idle with 256, 6% with 937; 5-9% faster,
    median of 10). Too many for ``n`` start a burst of episodes that ends in a long
    tail, hence about one per 64 transitions. With a policy the controls' noise
    follows the lockstep order, so its default stays fixed.
    """
    if policy is not None:
        return DEFAULT_PARALLEL
    return int(min(max(n // _TRANSITIONS_PER_SLOT, DEFAULT_PARALLEL), _MOST_PARALLEL))


class _EpisodeDraws:
    """Each episode's random actions and the controls they give, noise included.

    Episode e's first ``block`` steps come from two generators of the collection,
    ``block`` steps per episode in start order: actions from
    ``np.random.default_rng(seed)``, the controls' noise from its first spawned
    child. Its later blocks j = 1, 2, ... come from ``default_rng([seed, e, j])``
    (actions, then noise). So an episode's actions and noise depend on the seed
    and its number only: not on which episodes run beside it, nor on how many
    steps a C call takes, and an absorbing end cuts no call short.
    """

    def __init__(self, sim: _Simulator, task: Any, seed: int, slots: int, limit: float):
        self.sim, self.task, self.seed = sim, task, seed
        self.block = int(min(_BLOCK, np.ceil(limit)))
        self.actions_rng = np.random.default_rng(seed)
        self.noise_rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(1)[0])
        # Two blocks a slot, so that a call's steps may cross into the next one.
        self.actions = np.zeros((slots, 2 * self.block), np.int64)
        # Noise-free controls are a function of the action: mapped only for the
        # steps a call takes (cart-pole episodes take ~17 of a block's 256).
        self.noisy = bool(task.control_noise)
        self.controls = np.zeros((slots, 2 * self.block, sim.model.nu) if self.noisy else (0, 0, 0))
        self.base = np.zeros(slots, np.int64)  # each slot's episode step of column 0
        self.drawn = np.zeros(slots, np.int64)  # columns filled
        self.episode = np.zeros(slots, np.int64)

    def _draw(self, random: np.random.Generator | None, actions: np.ndarray) -> np.ndarray:
        controls = self.task.controls(self.sim.actions[actions.ravel()], random)
        return controls.reshape(*actions.shape, -1)

    def start(self, slots: np.ndarray, episodes: np.ndarray) -> None:
        """Draws the first blocks of ``episodes`` (consecutive, in start order) into ``slots``."""
        b = self.block
        actions = self.actions_rng.integers(len(self.sim.actions), size=(len(slots), b))
        self.actions[slots, :b] = actions
        if self.noisy:
            self.controls[slots, :b] = self._draw(self.noise_rng, actions)
        self.base[slots], self.drawn[slots], self.episode[slots] = 0, b, episodes

    def take(self, slots: np.ndarray, lengths: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Actions (k, m) and controls (k, m, nu) of the next ``k <= block`` steps of
        the episodes in ``slots``, which have taken ``lengths`` steps."""
        b = self.block
        offset = lengths - self.base[slots]
        spent = offset >= b  # the first block is behind them: move the second down
        if spent.any():
            s = slots[spent]
            self.actions[s, :b] = self.actions[s, b:]
            if self.noisy:
                self.controls[s, :b] = self.controls[s, b:]
            self.base[s] += b
            self.drawn[s] -= b
            offset[spent] -= b
        for slot in slots[offset + k > self.drawn[slots]]:
            column = self.drawn[slot]
            random = np.random.default_rng([self.seed, self.episode[slot], (self.base[slot] + column) // b])
            actions = random.integers(len(self.sim.actions), size=b)
            self.actions[slot, column : column + b] = actions
            if self.noisy:
                self.controls[slot, column : column + b] = self._draw(random, actions)
            self.drawn[slot] += b
        rows, columns = slots[:, None], offset[:, None] + np.arange(k)
        actions = self.actions[rows, columns].T
        if not self.noisy:
            return actions, self._draw(None, actions)
        return actions, self.controls[rows, columns].transpose(1, 0, 2)


class _Collection:
    """collect() on the batched path: episodes in lockstep, as documented there."""

    def __init__(
        self, sim: _Simulator, env: Any, n: int, n_parallel: int, limit: float, ended_before: np.ndarray | None = None
    ):
        self.sim, self.env, self.task, self.n, self.limit = sim, env, env.task, n, limit
        slots = min(n_parallel, n)
        self.batch = sim.new_batch(slots)
        self.episodes = _Episodes(n, ended_before)
        self.slot_episode = np.full(slots, -1, np.int64)
        # Each live slot's paper state: the last step's next state (reading it back from
        # the simulations would compute the same numbers again).
        self.slot_state = np.empty((slots, env.physics.STATE_SIZE))
        self.chunks: list[tuple[np.ndarray, ...]] = []
        self.c_seconds = 0.0  # spent in MuJoCo's calls

    def run(self, seed: int, policy: IndexPolicy | None) -> Transitions:
        sim, task = self.sim, self.task
        draws = _EpisodeDraws(sim, task, seed, len(self.slot_episode), self.limit) if policy is None else None
        n_actions = len(sim.actions)
        # What calls cost, to size them (_call_length): seconds outside the C calls,
        # seconds in them, simulation steps in them, calls.
        overhead = physics = sim_steps = calls = 0.0
        while True:
            began, in_c = time.perf_counter(), self.c_seconds
            starts = self.start_episodes()
            if draws is not None and len(starts):
                draws.start(starts, self.slot_episode[starts])
                if sim.legacy_first:  # the first steps replay the reset hooks, one step apart
                    self.step(starts, *draws.take(starts, np.zeros(len(starts), np.int64), 1))
            live = np.flatnonzero(self.slot_episode >= 0)
            if len(live) == 0:
                if len(starts):  # all of them ended in their first step: the schedule may start more
                    continue
                return _assemble(self.chunks, self.n)
            if draws is None:
                actions = _check_indices(policy(self.slot_state[live]), len(live), n_actions)[None]
                self.step(live, actions, task.controls(sim.actions[actions[0]], task.random)[None])
                continue
            ep = self.slot_episode[live]
            lengths = self.episodes.lengths[ep]
            # Steps after which each live episode is over or no longer needed.
            caps = np.minimum(np.ceil(self.limit - lengths), _steps_to_cover(ep, self.episodes, self.n))
            call_cost = overhead / calls / (physics / sim_steps) if calls else float(len(live))
            k = _call_length(self.episodes.ended, lengths, caps, call_cost, min(_MOST_STEPS, draws.block))
            self.step(live, *draws.take(live, lengths, k))
            in_c = self.c_seconds - in_c
            overhead, physics = overhead + time.perf_counter() - began - in_c, physics + in_c
            sim_steps, calls = sim_steps + k * len(live), calls + 1

    def start_episodes(self) -> np.ndarray:
        """Starts as many episodes as the schedule asks for; returns their slots."""
        episodes, slot_episode = self.episodes, self.slot_episode
        free = np.flatnonzero(slot_episode < 0)
        running = episodes.lengths[slot_episode[slot_episode >= 0]]
        n_start = _episodes_to_start(len(free), episodes.total(), self.n, episodes.ended, running, self.limit)
        starts = free[:n_start]
        if n_start:
            self.slot_state[starts] = self.sim.start_episodes(self.batch, starts, self.env)
            slot_episode[starts] = episodes.start(n_start)
        return starts

    def step(self, ids: np.ndarray, actions: np.ndarray, controls: np.ndarray) -> int:
        """``len(actions)`` control steps of the episodes in slots ``ids`` (sorted), recorded.

        An episode's steps end with its first absorbing or time-limit step; a
        simulation whose episode ended steps on idle to the end of the call.
        Returns how many episodes ended.
        """
        sim, task, episodes = self.sim, self.task, self.episodes
        k, m = actions.shape
        ep = self.slot_episode[ids]
        states, lengths = self.slot_state[ids], episodes.lengths[ep]
        began = time.perf_counter()
        stepped = sim.advance_steps(self.batch, ids, controls) if k > 1 else None
        if stepped is None:  # one step (or MuJoCo warned: step once, where divergence is handled)
            k, actions = 1, actions[:1]
            next_state, diverged = sim.advance(self.batch, ids, controls[0], lengths == 0)
            next_states = next_state[None]
        else:
            next_states, diverged = stepped, np.zeros(m, bool)
        self.c_seconds += time.perf_counter() - began
        flat = next_states.reshape(k * m, -1)
        rewards = np.asarray(task.batch_reward(flat), np.float64).reshape(k, m)
        absorbing = np.asarray(task.batch_absorbing(flat), bool).reshape(k, m)
        step = np.arange(1, k + 1)[:, None]
        timeout = lengths + step >= self.limit
        # dm_control: the time limit gives discount 1 even in a failure state;
        # a diverged step ends with discount 0, reward 0, the last finite state.
        absorbing &= ~timeout
        if diverged.any():
            absorbing[0] |= diverged
            next_states[0, diverged] = states[diverged]
            rewards[0, diverged] = 0.0
        last = absorbing | timeout
        ended = last.any(axis=0)
        taken = np.where(ended, np.argmax(last, axis=0) + 1, k)  # steps of each episode's own
        keep = step <= taken
        before = np.concatenate([states[None], next_states[:-1]])
        self.chunks.append(
            (
                np.broadcast_to(ep, (k, m))[keep],
                before[keep],
                actions[keep],
                rewards[keep],
                next_states[keep],
                absorbing[keep],
                last[keep],
            )
        )
        episodes.lengths[ep] = lengths + taken
        self.slot_state[ids] = next_states[taken - 1, np.arange(m)]
        episodes.end(ep[ended])
        done = ended | episodes.covered(ep)
        self.slot_episode[ids[done]] = -1
        return int(ended.sum())


def _call_length(ended: np.ndarray, ages: np.ndarray, caps: np.ndarray, call_cost: float, most: int) -> int:
    """Control steps for the next call: the most useful steps per cost (a speed choice only).

    ``ended``, ``ages``: as :func:`_expected_remaining` takes them; ``caps``: steps
    after which each live episode is over or not needed. A call of K steps costs
    K steps of every live simulation plus ``call_cost`` (the Python around it, in
    simulation steps); it is useful for the steps each episode takes before it
    ends, which a Kaplan-Meier survival S estimates: an episode of age a takes
    the call's step j + 1 with probability S(a + j) / S(a). No call reaches
    further than the longest length seen, so the first ones, before any episode
    ends, stay short.
    """
    m = len(ages)
    seen = np.flatnonzero(ended)
    most = int(min(most, max(1, seen[-1] if len(seen) else 0, ages.max()), caps.max()))
    survival = _survival(ended, ages, np.arange(int(ages.max()) + most + 1))  # S(t) = P(length > t)
    area = np.concatenate([[0.0], np.cumsum(survival)])  # sum of S(u) for u < t
    # Episodes of the same age and cap count alike: a few dozen kinds among up to 2,048.
    kinds, counts = np.unique(ages * (most + 1) + np.minimum(caps, most).astype(np.int64), return_counts=True)
    age, cap = np.divmod(kinds, most + 1)
    k = np.arange(1, most + 1)
    steps = np.minimum(k[:, None], cap[None, :])
    useful = ((area[age + steps] - area[age]) / survival[age]) @ counts
    return int(np.argmax(useful / (k * m + call_cost))) + 1


def _steps_to_cover(ep: np.ndarray, episodes: _Episodes, n: int) -> np.ndarray:
    """Steps after which each live episode in ``ep`` covers the first ``n`` transitions.

    Episode e is covered once the lengths of episodes 0..e add up to n; each
    step lengthens every live one among them by one.
    """
    live = np.zeros(episodes.count, np.int64)
    live[ep] = 1
    behind = np.cumsum(episodes.lengths[: episodes.count])[ep]
    return -((behind - n) // np.cumsum(live)[ep])


def _episodes_to_start(n_free: int, total: int, n: int, ended: np.ndarray, running: np.ndarray, limit: int) -> int:
    """How many new episodes ``collect`` starts now (at most ``n_free``).

    ``ended``, ``running``: as :func:`_expected_remaining` takes them.

    Start an episode only when the live ones are not expected to supply the
    transitions still missing: starting all slots at once would cut long
    (time-limited) episodes short and throw most of them away. The schedule
    depends on episode lengths only, so it is deterministic; it fixes which live
    episode gets which random action (drawn per lockstep), so changing it changes
    the data, never its distribution. Lengths are estimated with the running
    episodes' ages as censored observations (:func:`_expected_remaining`): 4% extra
    steps for 2x10^4 bicycle transitions, where the mean over ended episodes
    stepped 51%. A few episodes run at least while transitions are missing, so
    that the threads have work at once; none start once n are recorded.
    """
    if n_free == 0 or total >= n:
        return 0
    expected, remaining = _expected_remaining(ended, running, limit)
    supply_now = total + remaining.sum()
    if supply_now >= n and len(running) >= _MIN_LIVE:  # the usual answer, cheaply
        return 0
    # Starting k more: supply after k additions of ``expected`` (added one at a time,
    # as cumsum does) and k more live; the first k at which both suffice.
    supply = np.cumsum(np.concatenate([[supply_now], np.full(n_free, expected)]))
    enough = (supply >= n) & (len(running) + np.arange(n_free + 1) >= _MIN_LIVE)
    return int(np.argmax(enough)) if enough.any() else n_free


def _assemble(chunks: list[tuple[np.ndarray, ...]], n: int) -> Transitions:
    """The first ``n`` recorded transitions in (episode, step) order."""
    episode = np.concatenate([c[0] for c in chunks])
    if episode.max() < 2**16:  # numpy's stable sort is a radix sort for 16-bit keys: 6x faster
        episode = episode.astype(np.uint16)
    # Stable: steps of an episode were recorded in time order.
    order = np.argsort(episode, kind="stable")[:n]
    # np.take: 4x faster than indexing with ``order`` on the (n, d) state fields.
    fields = [np.take(np.concatenate([c[i] for c in chunks]), order, axis=0) for i in range(1, 7)]
    fields[5][-1] = True  # the collected segment ends here
    return Transitions(*fields)


def _collect_env(
    sim: _Simulator,
    n: int,
    seed: int,
    policy: IndexPolicy | None,
    max_episode_steps: int | None,
) -> Transitions:
    """A plain loop over one environment (time-varying models, tasks without physics);
    random actions from ``np.random.default_rng(seed)``."""
    env = sim.make_env(seed)
    rng = np.random.default_rng(seed)
    n_actions = len(sim.actions)
    state = _observed_state(env.reset())
    d = len(state)
    out = {
        "states": np.empty((n, d)),
        "actions": np.empty(n, np.int64),
        "rewards": np.empty(n),
        "next_states": np.empty((n, d)),
        "absorbing": np.zeros(n, bool),
        "last": np.zeros(n, bool),
    }
    i = 0
    while i < n:
        if i:
            state = _observed_state(env.reset())
        steps = 0
        while i < n:
            if policy is None:
                a = int(rng.integers(n_actions))
            else:
                a = int(_check_indices(policy(state[None]), 1, n_actions)[0])
            timestep = env.step(sim.actions[a])
            steps += 1
            next_state = _observed_state(timestep)
            out["states"][i], out["actions"][i], out["next_states"][i] = state, a, next_state
            out["rewards"][i] = timestep.reward
            out["absorbing"][i] = timestep.last() and timestep.discount == 0.0
            out["last"][i] = timestep.last() or steps == max_episode_steps
            i += 1
            if out["last"][i - 1]:
                break
            state = next_state
    out["last"][-1] = True
    _SUBSTEPS[sim.key] += n * sim.substeps
    return Transitions(**out)


def _collect_table(
    sim: _Simulator,
    n: int,
    seed: int,
    policy: IndexPolicy | None,
    max_episode_steps: int | None,
) -> Transitions:
    """:func:`_collect_env` on the task's known table (:class:`_Table`): the same resets,
    random actions and policy calls, in the same order, so the same transitions."""
    table = sim.table
    assert table is not None
    env = sim.make_env(seed)
    n_actions = len(sim.actions)
    # One action per transition, as _collect_env draws them one at a time: a Generator
    # gives the same integers in one call.
    drawn = np.random.default_rng(seed).integers(n_actions, size=n).tolist() if policy is None else None
    limit = table.episode_limit(max_episode_steps)
    next_list, reward_list, absorbing_list = table.next_list, table.reward_list, table.absorbing_list
    cells, next_cells, actions, rewards = [0] * n, [0] * n, [0] * n, [0.0] * n
    absorbing, last = np.zeros(n, bool), np.zeros(n, bool)
    i = 0
    while i < n:
        c, steps = table.cell(env.reset()), 0
        while i < n:
            if drawn is not None:
                a = drawn[i]
            else:
                a = int(_check_indices(policy(table.states[c : c + 1].copy()), 1, n_actions)[0])
            nxt = next_list[c][a]
            steps += 1
            cells[i], actions[i], rewards[i], next_cells[i] = c, a, reward_list[c][a], nxt
            absorbing[i] = absorbing_list[c][a]
            last[i] = absorbing[i] or steps == limit
            i += 1
            if last[i - 1]:
                break
            c = nxt
    last[-1] = True
    return Transitions(
        table.states[cells],
        np.asarray(actions, np.int64),
        np.asarray(rewards, np.float64),
        table.states[next_cells],
        absorbing,
        last,
    )


# --- One-step queries and evaluation ------------------------------------------------


def step_from(
    domain: str,
    task: str,
    states: np.ndarray,
    action_indices: np.ndarray,
    task_kwargs: dict[str, Any] | None = None,
    n_threads: int = 2,
) -> np.ndarray:
    """Next states after one control step from each of ``states`` (N, d).

    Each start is put in place as ``set_state_vector`` does (a fresh reset,
    then the paper state), and ``action_indices`` (N,) index ``ACTIONS``.
    Controls that draw noise use a ``RandomState(0)``. A step that diverges
    returns its start state, as the environment does. A task with a known
    exact model (``suite.describe(...).known_model``) answers from it.
    """
    sim = _simulator(domain, task, task_kwargs, n_threads)
    s = _check_states(states)
    a = _check_indices(action_indices, len(s), len(sim.actions))
    if not sim.fast:
        return _step_from_env(sim, s, a)
    return _step_values(sim, s, sim.actions[a])


def step_values_from(
    domain: str,
    task: str,
    states: np.ndarray,
    action_values: np.ndarray,
    task_kwargs: dict[str, Any] | None = None,
    n_threads: int = 2,
) -> np.ndarray:
    """Like :func:`step_from`, with actuator values (N, m) instead of action indices."""
    sim = _simulator(domain, task, task_kwargs, n_threads)
    s = _check_states(states)
    if not sim.fast:
        raise ValueError(f"{domain}/{task} is stepped through its environment; use step_from with action indices")
    return _step_values(sim, s, _check_values(action_values, len(s), sim))


def _check_states(states: Any) -> np.ndarray:
    s = np.asarray(states, np.float64)
    if s.ndim != 2 or not np.all(np.isfinite(s)):
        raise ValueError(f"states must be a finite (N, d) array, got shape {s.shape}")
    return s


def _step_values(sim: _Simulator, s: np.ndarray, values: np.ndarray) -> np.ndarray:
    if s.shape[1] != sim.physics.STATE_SIZE:
        raise ValueError(f"{sim.domain} states must have {sim.physics.STATE_SIZE} columns, got {s.shape[1]}")
    if len(s) == 0:
        return s.copy()
    batch = sim.query_batch(len(s))
    ids = np.arange(len(s))
    sim.place(batch, ids, *sim.physics.qpos_qvel_from(s))
    controls = sim.env.task.controls(values, _SeededOnUse(0))
    next_states, diverged = sim.advance(batch, ids, controls, np.ones(len(ids), bool))
    next_states[diverged] = s[diverged]
    return next_states


class _SeededOnUse:
    """``np.random.RandomState(seed)``, built on its first use.

    Most tasks' controls draw nothing, and building one costs about 0.13 ms, as
    much as the step itself (a horizon controller makes 10 such queries a decision).
    """

    def __init__(self, seed: int):
        self._seed = seed
        self._random: np.random.RandomState | None = None

    def __getattr__(self, name: str) -> Any:
        if self._random is None:
            self._random = np.random.RandomState(self._seed)
        return getattr(self._random, name)


def _step_from_env(sim: _Simulator, s: np.ndarray, a: np.ndarray) -> np.ndarray:
    """One step per query through the environment, or the task's known exact model."""
    if sim.table is not None:
        return sim.table.states[sim.table.next_state[sim.table.cell_map.index(s), a]]
    env = sim.env
    target = getattr(env, "physics", env)  # whichever holds set_state_vector
    out = np.empty_like(s)
    for i in range(len(s)):
        env.reset()
        target.set_state_vector(s[i])
        out[i] = _observed_state(env.step(sim.actions[a[i]]))
    _SUBSTEPS[sim.key] += len(s) * sim.substeps
    return out


def evaluate(
    domain: str,
    task: str,
    policy: ValuePolicy,
    n_episodes: int,
    seed: int,
    task_kwargs: dict[str, Any] | None = None,
    max_episode_steps: int | None = None,
    n_threads: int = 2,
) -> tuple[np.ndarray, np.ndarray]:
    """Undiscounted returns (n,) and lengths (n,) of ``policy`` over ``n_episodes``.

    All episodes run in lockstep from the task's start distribution (the
    successive resets of the task seeded with ``seed``); ``policy`` maps the
    (N, d) states of the live episodes to (N, action_dim) action values.

    The noise the task's controls draw (the bicycle's rider) is each episode's
    own: episode i's controls draw from its own Generator
    (:func:`_evaluation_randoms`), one call a step, so the noise of its step t
    depends on ``seed``, i and t alone, not on which other episodes still run:
    methods evaluated with one seed see common random numbers. Controls without
    noise draw nothing (``random=None``), one call for all live episodes.
    """
    n_episodes = integer("", "n_episodes", n_episodes, 1)
    if max_episode_steps is not None:
        integer("", "max_episode_steps", max_episode_steps, 1)
    sim = _simulator(domain, task, task_kwargs, n_threads)
    if sim.table is not None:
        return _evaluate_table(sim, policy, n_episodes, seed, max_episode_steps)
    if not sim.fast:
        return _evaluate_env(sim, policy, n_episodes, seed, max_episode_steps)
    limit = sim.step_limit(max_episode_steps)
    if not np.isfinite(limit):
        raise ValueError(f"{domain}/{task} has no time limit: give max_episode_steps")
    with sim.seeded_env(seed) as env:
        task_obj = env.task
        randoms = _evaluation_randoms(seed, n_episodes) if task_obj.control_noise else None
        # Optional in the domain contract: each row's controls from its own stream at once.
        controls_each = getattr(task_obj, "controls_each", None)
        batch = sim.new_batch(n_episodes)
        live = np.arange(n_episodes)
        states = sim.start_episodes(batch, live, env)
        returns = np.zeros(n_episodes)
        lengths = np.zeros(n_episodes, np.int64)
        while len(live):
            values = _check_values(policy(states), len(live), sim)
            if randoms is None:
                controls = task_obj.controls(values, None)
            elif controls_each is not None:  # the same draws in one call
                controls = controls_each(values, [randoms[i] for i in live])
            else:
                controls = np.concatenate(
                    [task_obj.controls(values[j : j + 1], randoms[i]) for j, i in enumerate(live)]
                )
            next_states, diverged = sim.advance(batch, live, controls, lengths[live] == 0)
            rewards = np.where(diverged, 0.0, task_obj.batch_reward(next_states))
            returns[live] += rewards
            lengths[live] += 1
            ended = diverged | task_obj.batch_absorbing(next_states) | (lengths[live] >= limit)
            live, states = live[~ended], next_states[~ended]
    return returns, lengths


def _evaluation_randoms(seed: int, n_episodes: int) -> list[np.random.Generator]:
    """Each evaluation episode's Generator for its controls' noise.

    Episode i's is child i of ``SeedSequence(seed)``'s second child (collect()'s
    noise starts from the first), whatever ``n_episodes``: its stream depends on
    the seed and its number only, and is apart from collect()'s with the same seed.
    """
    parent = np.random.SeedSequence(seed, spawn_key=(1,))
    return [np.random.default_rng(child) for child in parent.spawn(n_episodes)]


def _evaluate_env(
    sim: _Simulator,
    policy: ValuePolicy,
    n_episodes: int,
    seed: int,
    max_episode_steps: int | None,
) -> tuple[np.ndarray, np.ndarray]:
    """Lockstep over one environment per episode, seeded ``(seed, i)``: its start
    and any noise are episode i's own, as on the batched path (from another stream)."""
    envs = [sim.make_env(np.random.RandomState([seed, i])) for i in range(n_episodes)]
    states = np.stack([_observed_state(e.reset()) for e in envs])
    returns = np.zeros(n_episodes)
    lengths = np.zeros(n_episodes, np.int64)
    live = np.arange(n_episodes)
    while len(live):
        values = _check_values(policy(states[live]), len(live), sim)
        still = []
        for j, i in enumerate(live):
            timestep = envs[i].step(values[j])
            returns[i] += timestep.reward
            lengths[i] += 1
            states[i] = _observed_state(timestep)
            if not (timestep.last() or lengths[i] == max_episode_steps):
                still.append(i)
        live = np.asarray(still, np.int64)
    _SUBSTEPS[sim.key] += int(lengths.sum()) * sim.substeps
    return returns, lengths


def _evaluate_table(
    sim: _Simulator,
    policy: ValuePolicy,
    n_episodes: int,
    seed: int,
    max_episode_steps: int | None,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_evaluate_env` on the task's known table (:class:`_Table`): the same starts
    and policy calls, each live episode's step looked up."""
    table = sim.table
    assert table is not None
    envs = [sim.make_env(np.random.RandomState([seed, i])) for i in range(n_episodes)]
    cells = np.array([table.cell(e.reset()) for e in envs], np.int64)
    states = table.states[cells]
    returns = np.zeros(n_episodes)
    lengths = np.zeros(n_episodes, np.int64)
    limit = table.episode_limit(max_episode_steps)
    live = np.arange(n_episodes)
    while len(live):
        values = _check_values(policy(states[live]), len(live), sim)[:, 0]
        valid = np.isfinite(values) & (values >= 0) & (values < len(sim.actions))
        valid[valid] = values[valid] == np.floor(values[valid])
        if not valid.all():  # the environment's own error for an action it refuses
            j = int(np.argmin(valid))
            envs[live[j]].step(values[j : j + 1])
            raise ValueError(f"{sim.domain} action must be an index in 0..{len(sim.actions) - 1}, got {values[j]}")
        c, a = cells[live], values.astype(np.int64)
        returns[live] += table.reward[c, a]
        lengths[live] += 1
        cells[live] = table.next_state[c, a]
        states[live] = table.states[cells[live]]
        ended = table.absorbing[c, a] | (lengths[live] >= limit)
        live = live[~ended]
    return returns, lengths


def policy_transitions(
    env: dm_env.Environment,
    policy: Callable[[np.ndarray], np.ndarray],
    n: int,
    actions: np.ndarray,
    max_episode_steps: int | None = None,
) -> Transitions:
    """``n`` transitions of ``policy`` acting in ``env``, episode after episode from its resets.

    The paper's protocol for the apprentice's data ("randomly sampled starting
    positions, execute pi*(S) in the target"): load ``env`` with its random start
    and ``random`` seed. ``policy`` maps a (1, d) state to (1,) indices into
    ``actions`` (what ``env.step`` takes for each index). Episodes end at the task's
    own end or after ``max_episode_steps``; the last one is cut at ``n``.
    ``absorbing`` marks ends with discount 0 and ``last`` each episode's final transition.
    """
    n = integer("", "n", n, 1)
    if max_episode_steps is not None:
        integer("", "max_episode_steps", max_episode_steps, 1)
    rows: dict[str, list] = {k: [] for k in ("states", "actions", "rewards", "next_states", "absorbing", "last")}
    while len(rows["states"]) < n:
        timestep = env.reset()
        state, steps = _observed_state(timestep), 0
        while len(rows["states"]) < n:
            index = _check_indices(policy(state[None]), 1, len(actions))[0]
            timestep = env.step(actions[index])
            steps += 1
            next_state = _observed_state(timestep)
            last = timestep.last() or steps == max_episode_steps or len(rows["states"]) + 1 == n
            for key, value in (
                ("states", state),
                ("actions", index),
                ("rewards", timestep.reward),
                ("next_states", next_state),
                ("last", last),
                ("absorbing", timestep.last() and timestep.discount == 0.0),
            ):
                rows[key].append(value)
            if last:
                break
            state = next_state
    return Transitions(**{k: np.asarray(v) for k, v in rows.items()})


def start_states(
    domain: str, task: str, n_episodes: int, seed: int, task_kwargs: dict[str, Any] | None = None
) -> np.ndarray:
    """(n, d) the start states of ``evaluate(domain, task, ..., n_episodes, seed)``'s episodes.

    So a model can be scored from exactly the states a real rollout starts from
    (Algorithm 2 compares U_M and U_Mhat from the same starts).
    """
    n = integer("", "n_episodes", n_episodes, 1)
    sim = _simulator(domain, task, task_kwargs, 1)
    if not sim.fast:
        envs = [sim.make_env(np.random.RandomState([seed, i])) for i in range(n)]
        return np.stack([_observed_state(e.reset()) for e in envs])
    with sim.seeded_env(seed) as env:
        qpos, qvel = env.task.start_configurations(env.physics, n)
        return sim.physics.states_from(qpos, qvel)
