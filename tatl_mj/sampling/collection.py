"""collect(): exactly ``n`` transitions of whole episodes, in episode order.

On the batched path the live episodes are rows of one Batch, stepped in
lockstep; ``collect`` returns the first ``n`` transitions of the episodes in
start order, so the data are what a sequential loop would collect. It starts
episodes only as fast as they are expected to be needed (:mod:`.schedule`), so
that long (time-limited) episodes are not cut short and thrown away. With
random actions, each episode draws its actions, and the noise its controls
carry, from its own blocks of random numbers (:class:`EpisodeDraws`), so the
data depend on the seed alone; the live episodes then take several control
steps in one ``Batch.rollout`` call, and an episode that ends in it idles to
the call's end (how many steps a call takes is a speed choice,
:func:`schedule.call_length`).

Tasks stepped through their environment run one plain loop over it
(:func:`_environment_loop`), which :func:`policy_transitions` runs on a given
environment; a task with a known table runs the same loop with the table's
steps looked up instead of the environment's. One whose model depends on the
step alone runs that loop's episodes in lockstep where its actions' draws can
be made first (:func:`_collect_scheduled`): the same transitions.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from typing import Any, Callable

import dm_env
import numpy as np

from tatl_mj.policy import StatePolicy
from tatl_mj.sampling import schedule
from tatl_mj.sampling.checks import DrawingPolicy, IndexPolicy, check_indices
from tatl_mj.sampling.simulator import SUBSTEPS, Simulator, Table, episode_simulator, observed_state
from tatl_mj.transitions import Transitions
from tatl_mj.validation import integer

BLOCK = 256  # control steps of an episode's random actions drawn at a time (>= schedule.MOST_STEPS)


def collect(
    domain: str,
    task: str,
    n_transitions: int,
    seed: int,
    policy: IndexPolicy | None = None,
    task_kwargs: dict[str, Any] | None = None,
    max_episode_steps: int | None = None,
    n_threads: int | None = None,
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
    to 2048 (:func:`schedule.default_parallel`).

    Random actions, and the noise the task's controls draw with them (the
    bicycle's rider), are each episode's own (:class:`EpisodeDraws`): the
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
    n_parallel = (
        schedule.default_parallel(n, policy is None) if n_parallel is None else integer("", "n_parallel", n_parallel, 1)
    )
    sim = episode_simulator(domain, task, task_kwargs, n_threads, max_episode_steps)
    if not sim.fast:
        return _collect_loop(sim, n, seed, policy, max_episode_steps)
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


class EpisodeDraws:
    """Each episode's random actions and the controls they give, noise included.

    Episode e's first ``block`` steps come from two generators of the collection,
    ``block`` steps per episode in start order: actions from
    ``np.random.default_rng(seed)``, the controls' noise from its first spawned
    child. Its later blocks j = 1, 2, ... come from ``default_rng([seed, e, j])``
    (actions, then noise). So an episode's actions and noise depend on the seed
    and its number only: not on which episodes run beside it, nor on how many
    steps a C call takes, and an absorbing end cuts no call short.
    """

    def __init__(self, sim: Simulator, task: Any, seed: int, slots: int, limit: float):
        self.sim, self.task, self.seed = sim, task, seed
        self.block = int(min(BLOCK, np.ceil(limit)))
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
        self, sim: Simulator, env: Any, n: int, n_parallel: int, limit: float, ended_before: np.ndarray | None = None
    ):
        self.sim, self.env, self.task, self.n, self.limit = sim, env, env.task, n, limit
        slots = min(n_parallel, n)
        self.batch = sim.new_batch(slots)
        self.episodes = schedule.Episodes(n, ended_before)
        self.slot_episode = np.full(slots, -1, np.int64)
        # Each live slot's paper state: the last step's next state (reading it back from
        # the simulations would compute the same numbers again).
        self.slot_state = np.empty((slots, env.physics.STATE_SIZE))
        self.chunks: list[tuple[np.ndarray, ...]] = []
        self.c_seconds = 0.0  # spent in MuJoCo's calls

    def run(self, seed: int, policy: IndexPolicy | None) -> Transitions:
        sim, task = self.sim, self.task
        draws = EpisodeDraws(sim, task, seed, len(self.slot_episode), self.limit) if policy is None else None
        n_actions = len(sim.actions)
        # What calls cost, to size them (schedule.call_length): seconds outside the C calls,
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
                actions = check_indices(policy(self.slot_state[live]), len(live), n_actions)[None]
                self.step(live, actions, task.controls(sim.actions[actions[0]], task.random)[None])
                continue
            ep = self.slot_episode[live]
            lengths = self.episodes.lengths[ep]
            # Steps after which each live episode is over or no longer needed.
            caps = np.minimum(np.ceil(self.limit - lengths), schedule.steps_to_cover(ep, self.episodes, self.n))
            call_cost = overhead / calls / (physics / sim_steps) if calls else float(len(live))
            k = schedule.call_length(
                self.episodes.ended, lengths, caps, call_cost, min(schedule.MOST_STEPS, draws.block)
            )
            self.step(live, *draws.take(live, lengths, k))
            in_c = self.c_seconds - in_c
            overhead, physics = overhead + time.perf_counter() - began - in_c, physics + in_c
            sim_steps, calls = sim_steps + k * len(live), calls + 1

    def start_episodes(self) -> np.ndarray:
        """Starts as many episodes as the schedule asks for; returns their slots."""
        episodes, slot_episode = self.episodes, self.slot_episode
        free = np.flatnonzero(slot_episode < 0)
        running = episodes.lengths[slot_episode[slot_episode >= 0]]
        n_start = schedule.episodes_to_start(len(free), episodes.total(), self.n, episodes.ended, running, self.limit)
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


def _collect_loop(
    sim: Simulator,
    n: int,
    seed: int,
    policy: IndexPolicy | None,
    max_episode_steps: int | None,
) -> Transitions:
    """collect() through one environment (time-varying models, tasks without physics),
    random actions from ``np.random.default_rng(seed)``, one a step (a
    :class:`DrawingPolicy`'s draws made first, in the same order); a task with a known
    table (:class:`Table`) looks its steps up instead, with the same resets, random
    actions and policy calls in the same order, so the same transitions."""
    env, n_actions, table = sim.make_env(seed), len(sim.actions), sim.table
    if table is None:
        drawing = _RandomActions(np.random.default_rng(seed), n_actions) if policy is None else policy
        if isinstance(drawing, DrawingPolicy):
            # Every call's draws first, then the calls: the same actions, in lockstep where it can.
            draws = drawing.draws(n)
            if sim.step_env is not None and not sim.env.task.control_noise:
                scheduled = _collect_scheduled(sim, n, seed, drawing, draws, max_episode_steps)
                if scheduled is not None:
                    return scheduled
            rows = iter(range(n))
            choose = lambda state: _one_action(drawing.act(state[None], draws[next(rows)][None]), n_actions)  # noqa: E731
        else:
            choose = _policy_choice(policy, n_actions)  # type: ignore[arg-type]
        transitions = _environment_loop(*_stepping(env, sim.actions), choose, n, max_episode_steps)
        SUBSTEPS[sim.key] += n * sim.substeps
        return transitions
    if policy is None:
        # One action per transition, drawn one at a time above: a Generator gives the
        # same integers in one call.
        drawn = iter(np.random.default_rng(seed).integers(n_actions, size=n).tolist())
        choose = lambda cell: next(drawn)  # noqa: E731
    elif isinstance(policy, DrawingPolicy):
        # Every call's draws first, then each step answered with its row: the same actions.
        draws, rows = policy.draws(n), iter(range(n))

        def choose(cell: int) -> int:
            return _one_action(policy.act(table.states[cell : cell + 1], draws[next(rows)][None]), n_actions)

    else:
        by_state = _policy_choice(policy, n_actions)

        def choose(cell: int) -> int:
            return by_state(table.states[cell].copy())

        if isinstance(policy, StatePolicy):  # a function of the state alone: its first answer in a cell stands
            choose = functools.cache(choose)

    return _environment_loop(*_table_stepping(env, table), choose, n, table.episode_limit(max_episode_steps))


def _policy_choice(policy: IndexPolicy, n_actions: int) -> Callable[[np.ndarray], int]:
    """The action index ``policy`` takes in one state, checked."""
    return lambda state: _one_action(policy(state[None]), n_actions)


def _one_action(indices: Any, n_actions: int) -> int:
    return int(check_indices(indices, 1, n_actions)[0])


@dataclasses.dataclass(frozen=True)
class _RandomActions:
    """Uniformly random indices, one a call from ``rng``, as a :class:`DrawingPolicy`."""

    rng: np.random.Generator
    n_actions: int

    def __call__(self, states: np.ndarray) -> np.ndarray:
        return self.rng.integers(self.n_actions, size=len(states))

    def draws(self, calls: int) -> np.ndarray:
        # One call gives the integers that ``calls`` calls of one each give.
        return self.rng.integers(self.n_actions, size=(calls, 1))

    def act(self, states: np.ndarray, draws: np.ndarray) -> np.ndarray:
        return draws[:, 0]


def _collect_scheduled(
    sim: Simulator,
    n: int,
    seed: int,
    policy: DrawingPolicy,
    draws: np.ndarray,
    max_episode_steps: int | None,
) -> Transitions | None:
    """:func:`_collect_loop`'s transitions on a task whose model depends on the step alone
    (``model_for_step``): its episodes run in lockstep, each control step of all of them
    on the one model of that step.

    The plain loop's episodes are the successive resets of one environment seeded
    ``seed``, each running to its step limit, the last cut at ``n``; episode e's step t
    is its call e * limit + t, which drew ``draws[e * limit + t]``. Where an episode
    ends sooner (absorbing, diverged) later calls move, so None is returned and the
    plain loop runs instead.
    """
    limit = min(sim.step_limit(None), np.inf if max_episode_steps is None else max_episode_steps)
    if not np.isfinite(limit):
        return None
    length = int(np.ceil(limit))
    n_episodes = -(-n // length)
    env, task = sim.make_env(seed), sim.env.task
    starts = []
    for _ in range(n_episodes):
        env.reset()
        starts.append((np.array(env.physics.data.qpos), np.array(env.physics.data.qvel)))
    qpos, qvel = (np.stack(column) for column in zip(*starts))
    batch = sim.new_batch(n_episodes)
    model_for = sim.scheduled_models(batch)
    episodes = np.arange(n_episodes)
    sim.place(batch, episodes, qpos, qvel)
    state = sim.physics.states_from(qpos, qvel)
    taken = np.minimum(length, n - episodes * length)  # the transitions each episode gives
    states = np.empty((n_episodes, length, state.shape[1]))
    next_states, actions, rewards = (
        np.empty_like(states),
        np.zeros((n_episodes, length), np.int64),
        np.zeros((n_episodes, length)),
    )
    for t in range(length):
        live = episodes[taken > t]
        chosen = check_indices(policy.act(state[live], draws[live * length + t]), len(live), len(sim.actions))
        model_for(t)
        after, diverged = sim.advance(batch, live, task.controls(sim.actions[chosen], None), np.full(len(live), t == 0))
        if diverged.any() or task.batch_absorbing(after).any():
            return None
        states[live, t], actions[live, t], next_states[live, t] = state[live], chosen, after
        rewards[live, t] = task.batch_reward(after)
        state[live] = after
    kept = np.arange(length)[None, :] < taken[:, None]  # episode by episode, step by step
    last = np.zeros((n_episodes, length), bool)
    last[episodes, taken - 1] = True
    return Transitions(states[kept], actions[kept], rewards[kept], next_states[kept], np.zeros(n, bool), last[kept])


Reset = Callable[[], Any]
"""Starts an episode; returns its first state (a key of the stepping: a state vector or a cell)."""
Step = Callable[[Any, int], tuple[Any, float, bool, bool]]
"""``step(state, a)`` -> (next state, reward, absorbing, the task ended the episode)."""


def _stepping(env: dm_env.Environment, actions: np.ndarray) -> tuple[Reset, Step, Callable[[list], np.ndarray]]:
    """``env``'s resets and steps taking ``actions[a]``, over state vectors."""

    def step(state: np.ndarray, a: int) -> tuple[np.ndarray, float, bool, bool]:
        timestep = env.step(actions[a])
        # A copy: the records keep every state, and an observation may be a view of the physics.
        return (
            observed_state(timestep).copy(),
            timestep.reward,
            timestep.last() and timestep.discount == 0.0,
            timestep.last(),
        )

    return lambda: observed_state(env.reset()).copy(), step, lambda states: np.asarray(states, np.float64)


def _table_stepping(env: dm_env.Environment, table: Table) -> tuple[Reset, Step, Callable[[list], np.ndarray]]:
    """``env``'s resets and ``table``'s steps, over cells."""
    next_list, reward_list, absorbing_list = table.next_list, table.reward_list, table.absorbing_list

    def step(c: int, a: int) -> tuple[int, float, bool, bool]:
        return next_list[c][a], reward_list[c][a], absorbing_list[c][a], absorbing_list[c][a]

    return lambda: table.cell(env.reset()), step, lambda cells: table.states[cells]


def _environment_loop(
    reset: Reset,
    step: Step,
    states_of: Callable[[list], np.ndarray],
    choose: Callable[[Any], int],
    n: int,
    limit: int | None,
) -> Transitions:
    """``n`` transitions, episode after episode from ``reset()``, taking ``choose(state)``
    through ``step``; an episode also ends after ``limit`` steps, the last one is cut
    at ``n``. ``states_of`` turns the recorded states (or cells) into the (n, d) field."""
    states, actions, rewards, next_states = [None] * n, np.empty(n, np.int64), np.empty(n), [None] * n
    absorbing, last = np.zeros(n, bool), np.zeros(n, bool)
    i = 0
    while i < n:
        state, steps = reset(), 0
        while i < n:
            a = choose(state)
            next_state, rewards[i], absorbing[i], ended = step(state, a)
            steps += 1
            states[i], actions[i], next_states[i] = state, a, next_state
            last[i] = ended or steps == limit
            i += 1
            if last[i - 1]:
                break
            state = next_state
    last[-1] = True
    return Transitions(states_of(states), actions, rewards, states_of(next_states), absorbing, last)


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
    return _environment_loop(*_stepping(env, actions), _policy_choice(policy, len(actions)), n, max_episode_steps)
