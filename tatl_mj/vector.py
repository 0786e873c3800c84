"""A native Gymnasium vector env: N simulations of a task stepped in one batched MuJoCo call.

>>> import gymnasium as gym, tatl_mj.gym
>>> envs = gym.make_vec("tatl_mj/BicycleBalance-v2", num_envs=64, vectorization_mode="vector_entry_point")
>>> observations, infos = envs.reset(seed=0)          # env i is seeded 0 + i
>>> observations, rewards, terminated, truncated, infos = envs.step(envs.action_space.sample())

Each env is one simulation of a ``mujoco.batch.Batch``, stepped through the
batched sampler's machinery (``tatl_mj.sampling.simulator``: one C call a
control step for all N, on ``n_threads`` MuJoCo threads), with the task's
reward, termination and controls applied to the whole batch through the domain
contract (``batch_reward``, ``batch_absorbing``, ``controls``).

What makes env i's transitions those of the single env (``gym.make(id)``) reset
with seed ``seed + i`` and given the same actions, bit for bit (tested):

- every env has its task's own random state (a ``suite.load`` of its own,
  seeded at ``reset(seed=...)``): its start states and the noise its controls
  carry (the bicycle rider's) are drawn from it in the single env's order;
- a task whose model changes every step (the time-varying pendulum,
  ``model_for_step``) runs each simulation on the model of its own episode's
  step, since autoreset takes the envs out of lockstep: each step's model is
  made once, by the task itself, and its changed fields are written per
  simulation (:class:`StepModels`);
- episodes end as the single env's do: ``terminated`` at an absorbing state or
  a diverged simulation (reward 0, the last finite state, ``info["diverged"]``),
  ``truncated`` at the task's time limit (``task_kwargs["time_limit"]``) or
  ``max_episode_steps``, whichever comes first.

Autoreset follows Gymnasium 1.x's default, ``AutoresetMode.NEXT_STEP``: the
step after an episode ends resets that env (its action is ignored, its reward
0). ``autoreset_mode=AutoresetMode.SAME_STEP`` resets it within the step that
ended it, the last observation in ``info["final_obs"]`` (what
``tatl_mj.sb3``'s adapter uses). ``reset(options={"reset_mask": mask})`` resets
only the envs in ``mask``.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium
import mujoco
import mujoco.batch
import numpy as np
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from tatl_mj import gym as tatl_gym
from tatl_mj import suite
from tatl_mj.sampling.simulator import controls_each, episode_simulator
from tatl_mj.suite import ContextSampler
from tatl_mj.validation import integer
from tatl_mj.vector_contexts import SimContexts, model_field

AUTORESET_MODES: tuple[AutoresetMode, ...] = (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP)


class TatlVectorEnv(gymnasium.vector.VectorEnv):
    """``num_envs`` copies of a tatl-mj physics task in one batch (see the module docstring)."""

    metadata: dict[str, Any] = {
        "render_modes": list(tatl_gym.RENDER_MODES),
        "render_fps": None,
        "autoreset_mode": AutoresetMode.NEXT_STEP,
    }

    def __init__(
        self,
        domain: str,
        task: str,
        num_envs: int = 1,
        task_kwargs: dict[str, Any] | None = None,
        max_episode_steps: int | None = None,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 480,
        camera: str | None = None,
        normalize_actions: bool = True,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        n_threads: int | None = None,
        contexts: Sequence[Mapping[str, Any]] | ContextSampler | None = None,
        context_in_observation: bool = False,
    ) -> None:
        tatl_gym.check_physics_task(domain, task)
        tatl_gym.check_render_mode(render_mode)
        self.num_envs = integer("", "num_envs", num_envs, 1)
        self.autoreset_mode = _autoreset_mode(autoreset_mode)
        kwargs = dict(task_kwargs or {})
        random = _start_seed(kwargs.pop("random", None))
        # Checked before anything is built; also what the observation carries with context_in_observation.
        self._contexts = _contexts(domain, task, kwargs, contexts, context_in_observation, self.num_envs)
        self._context_in_observation = context_in_observation
        self._sim = episode_simulator(domain, task, kwargs, n_threads, max_episode_steps)
        if not self._sim.batched_queries:
            raise ValueError(
                f"{domain}/{task} changes its model during an episode in a way that depends on more than the "
                "step (no model_for_step): it has no batched vector env; use vectorization_mode='sync'"
            )
        # One environment for the task's rules and a scratch physics; each simulation keeps its own
        # random stream, as its single env's task would (dm_control seeds a task with RandomState).
        self._env = suite.load(domain, task, task_kwargs={**kwargs, "random": random})
        self._randoms = [np.random.RandomState(random) for _ in range(self.num_envs)]
        self._task = self._env.task
        self._noisy = bool(self._task.control_noise)
        # Task keys of the contexts go to the task's controls_each, row by row.
        self._per_row = self._contexts is not None and bool(self._contexts.task_columns)

        limit = tatl_gym.actuator_limit(self._env, f"{domain}/{task}")
        self.single_action_space, self._scale = tatl_gym.action_space(limit, normalize_actions)
        extra = len(self._contexts.names) if context_in_observation and self._contexts is not None else 0
        self.single_observation_space = tatl_gym.observation_space(self._sim.physics.STATE_SIZE + extra)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        control_timestep = self._env.control_timestep()
        self.metadata = {
            **type(self).metadata,
            "render_fps": int(round(1.0 / control_timestep)),
            "autoreset_mode": self.autoreset_mode,
        }
        self.render_mode = render_mode
        self._frame_size = (height, width)
        self._camera = tatl_gym.default_camera(domain, camera)
        self._canvas: Any = None
        self._camera_id, self._render_model = -1, None

        # Episodes end by time limit after the task's steps or max_episode_steps, the fewer.
        self._task_steps = tatl_gym.episode_steps(self._env, domain, task, kwargs) or np.inf
        self._limit = min(self._task_steps, max_episode_steps or np.inf)
        self._batch = self._sim.new_batch(self.num_envs)
        # A model per step of an episode (model_for_step): per-simulation fields of the batch.
        if self._contexts is not None:
            self._contexts.bind(self._env, self._batch, per_step=not self._sim.fast)
        if self._sim.fast or self._contexts is not None:
            self._schedule = None  # contexts write each step's models themselves (write_models)
        else:
            self._schedule = StepModels(self._task, self._env.physics, self._batch, self._limit)
        self._all = np.arange(self.num_envs)
        self._states = np.zeros((self.num_envs, self._sim.physics.STATE_SIZE))
        self._steps = np.zeros(self.num_envs, np.int64)
        self._autoreset = np.zeros(self.num_envs, bool)
        self._started = False

    @property
    def max_episode_steps(self) -> int | None:
        """Steps after which an episode ends by time limit (None: never)."""
        return None if self._limit == np.inf else int(self._limit)

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Resets every env (or those of ``options["reset_mask"]``); ``seed`` s seeds env i with
        s + i, a list seeds env i with its item (None: its random state goes on)."""
        seeds = _seeds(seed, self.num_envs)
        options = dict(options or {})
        mask = options.pop("reset_mask", None)
        if options:
            raise ValueError(f"unknown reset options {sorted(options)}; valid: ['reset_mask']")
        ids = self._all if mask is None else self._all[_checked_mask(mask, self.num_envs)]
        super().reset(seed=seeds[0] if isinstance(seed, (int, np.integer)) else None)
        for i in ids:
            if seeds[i] is not None:
                self._randoms[i].seed(seeds[i])
        if self._contexts is not None and isinstance(seed, (int, np.integer)):
            self._contexts.reseed(int(seed))
        self._start(ids)
        self._started = True
        return self._observations(), self._context_info({})

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if not self._started:
            raise ValueError("call reset() before step(): no episode has started")
        values = tatl_gym.actuator_values(actions, self.action_space, self._scale)
        n = self.num_envs
        rewards = np.zeros(n)
        terminated = np.zeros(n, bool)
        truncated = np.zeros(n, bool)
        info: dict[str, Any] = {}
        resetting = self._autoreset
        ids = self._all if not resetting.any() else self._all[~resetting]
        if len(ids) < n:
            self._start(self._all[resetting])  # NEXT_STEP: these only start their next episode
        if len(ids):
            steps = self._steps[ids]
            noisy = self._noisy if self._contexts is None else self._contexts.noisy[ids].any()
            randoms = [self._randoms[i] for i in ids] if noisy else None
            per_row = self._contexts.task_arrays(ids) if self._per_row else None  # type: ignore[union-attr]
            controls = controls_each(self._task, values[ids], randoms, per_row)
            if self._schedule is not None:
                self._schedule.set(self._steps)
            elif self._contexts is not None and self._contexts.per_step:
                self._contexts.write_models(ids, steps)
            next_states, diverged = self._sim.advance(self._batch, ids, controls, steps == 0)
            steps += 1
            self._steps[ids] = steps
            reward = self._task.batch_reward(next_states)
            absorbing = self._task.batch_absorbing(next_states)
            # dm_control: the time limit ends an episode with discount 1 even in an absorbing
            # state; a diverged step ends with discount 0, reward 0 and the last finite state.
            end = diverged | (absorbing & (steps < self._task_steps))
            if diverged.any():
                reward = np.where(diverged, 0.0, reward)
                next_states[diverged] = self._states[ids[diverged]]
                messages = np.full(n, None, dtype=object)
                messages[ids[diverged]] = [self._diverged_message(i) for i in ids[diverged]]
                info["diverged"], info["_diverged"] = messages, messages != None  # noqa: E711
            rewards[ids], terminated[ids], truncated[ids] = reward, end, steps >= self._limit
            self._states[ids] = next_states
        observations = self._observations()
        done = terminated | truncated
        if self.autoreset_mode is AutoresetMode.SAME_STEP and done.any():
            final = np.full(n, None, dtype=object)
            for i in np.flatnonzero(done):
                final[i] = observations[i].copy()  # with the context of the episode that ended
            info["final_obs"], info["_final_obs"] = final, done.copy()
            self._start(self._all[done])
            observations = self._observations()
            self._autoreset = np.zeros(n, bool)
        else:
            self._autoreset = done
        return observations, rewards, terminated, truncated, self._context_info(info)

    def render(self) -> tuple[np.ndarray, ...] | None:
        """Each env's frame, from the camera the domain declares (or ``camera``)."""
        if self.render_mode is None:
            return None
        from tatl_mj import gl

        height, width = self._frame_size
        if self._canvas is None:
            self._canvas = gl.Canvas(self._sim.model, height, width)
            self._camera_id = self._sim.physics.model.name2id(self._camera, "camera")
            # Scratch for each env's own model; copied once, as a model copy carries its textures.
            per_sim = self._schedule is not None or self._contexts is not None
            self._render_model = copy.copy(self._sim.model) if per_sim else None
        camera, model = self._camera_id, self._render_model
        data = self._env.physics.data.ptr  # scratch: the env's own physics is never stepped
        last = np.maximum(self._steps - 1, 0)  # the model of each env's last step, as the single env shows
        if self._schedule is not None:
            self._schedule.set(last)
        elif self._contexts is not None and self._contexts.per_step:
            self._contexts.write_models(self._all, last)
        frames = []
        for i in self._all:
            if model is not None:
                self._batch.get_model(int(i), model)  # with its step's sizes and masses
            self._batch.get_data(int(i), data)
            mujoco.mj_forward(self._sim.model if model is None else model, data)  # poses from the state
            frames.append(self._canvas.draw(data, camera, model=model))
        return tuple(frames)

    def close_extras(self, **kwargs: Any) -> None:
        if self._canvas is not None:
            self._canvas.close()
            self._canvas = None

    def _start(self, ids: np.ndarray) -> None:
        """Starts the next episode of envs ``ids``, each drawn from its own random stream (lent to
        the task for the draw, then taken back)."""
        shared = self._env.task.random
        if self._contexts is not None:
            self._contexts.start(ids)  # a sampler's new contexts, and the models they make
        for i in ids:
            if self._contexts is not None:
                self._contexts.lend(int(i))  # the task keys of env i's context, for its draw
            shared.set_state(self._randoms[i].get_state())
            self._states[i] = self._sim.start_episodes(self._batch, np.array([i]), self._env)[0]
            self._randoms[i].set_state(shared.get_state())
        self._steps[ids] = 0
        self._autoreset[ids] = False

    def _observations(self) -> np.ndarray:
        """The states, each followed by its env's context values with ``context_in_observation``."""
        if not self._context_in_observation:
            return self._states.copy()
        return np.concatenate([self._states, self._contexts.values], axis=1)  # type: ignore[union-attr]

    def _context_info(self, info: dict[str, Any]) -> dict[str, Any]:
        """``info`` with every env's context (key -> (num_envs,) values), where the env has contexts."""
        if self._contexts is not None:
            info["context"], info["_context"] = self._contexts.info(), np.ones(self.num_envs, bool)
        return info

    def _diverged_message(self, i: int) -> str:
        """dm_control's message for simulation ``i``'s warnings (the single env's ``info["diverged"]``)."""
        raised = np.compress(self._batch.warning[i, :, 1] > 0, list(mujoco.mjtWarning.__members__))
        return f"Physics state is invalid. Warning(s) raised: {', '.join(raised)}"


class StepModels:
    """Each simulation's model at its own episode's step, for a task whose model depends on the
    step alone (``model_for_step``): per-simulation fields of the batch (``Batch.expand``).

    The model of step k is made once, by the task itself on a scratch ``physics``
    (derived constants included); the fields in which it differs from the batch's
    model are kept, a row per step, and each call of :meth:`set` writes every
    simulation's row. Copying whole models instead would copy their textures
    too (megabytes, milliseconds each). The steps of a whole episode (up to
    ``AHEAD``) are made at once, when the env is made, so that stepping never
    waits for them.
    """

    AHEAD = 1024  # steps made when the env is made, if an episode lasts that long

    def __init__(self, task: Any, physics: Any, batch: Any, episode_steps: float) -> None:
        self.task, self.physics, self.batch = task, physics, batch
        model = batch.get_model(0)
        self.base = {name: np.array(model_field(model, name)) for name in mujoco.batch.MODEL_FIELDS}
        self.tables: dict[str, np.ndarray] = {}  # field -> its value at steps 0, 1, ... (rows known)
        self.live: dict[str, np.ndarray] = {}  # field -> the batch's per-simulation values
        self.known = 0
        self._make(int(min(episode_steps, self.AHEAD)))

    def set(self, steps: np.ndarray) -> None:
        """Gives simulation i the model of its episode's step ``steps[i]``."""
        self._make(int(steps.max()) + 1)
        for name, live in self.live.items():
            live[:] = self.tables[name][steps]

    def _make(self, needed: int) -> None:
        """Makes the rows of steps up to ``needed - 1``, the tables grown by doubling."""
        if needed <= self.known:
            return
        capacity = max(needed, 2 * self.known)
        for name, table in self.tables.items():
            grown = np.empty((capacity, *table.shape[1:]), table.dtype)
            grown[: len(table)] = table
            self.tables[name] = grown
        while self.known < needed:
            self._add(self.known, capacity)

    def _add(self, step: int, capacity: int) -> None:
        self.task.model_for_step(self.physics, step)
        model = self.physics.model.ptr
        for name, base in self.base.items():
            value = np.asarray(model_field(model, name))
            if name not in self.tables and value.tobytes() != base.tobytes():
                # First seen to change at this step: the earlier steps had the batch's value.
                self.tables[name] = np.empty((capacity, *base.shape), base.dtype)
                self.tables[name][:step] = base
                self.live[name] = self.batch.expand(name)
            if name in self.tables:
                self.tables[name][step] = value
        self.known = step + 1


def _start_seed(random: Any) -> int | None:
    if random is not None and (isinstance(random, bool) or not isinstance(random, (int, np.integer))):
        raise ValueError(
            f"task_kwargs['random'] must be None or an integer seed (every env starts from it, "
            f"as make_vec's single envs would; or seed through reset(seed=...)), got {random!r}"
        )
    return random


def _contexts(
    domain: str, task: str, kwargs: dict[str, Any], contexts: Any, in_observation: Any, num_envs: int
) -> SimContexts | None:
    """The envs' contexts, checked (None: neither contexts nor ``context_in_observation``)."""
    if not isinstance(in_observation, bool):
        raise ValueError(f"context_in_observation must be True or False, got {in_observation!r}")
    if contexts is None and not in_observation:
        return None
    return SimContexts(domain, task, kwargs, contexts, num_envs)


def _autoreset_mode(mode: AutoresetMode | str) -> AutoresetMode:
    try:
        chosen = AutoresetMode(mode)
    except ValueError:
        chosen = None
    if chosen not in AUTORESET_MODES:
        raise ValueError(f"autoreset_mode must be one of {[m.value for m in AUTORESET_MODES]}, got {mode!r}")
    return chosen


def _seeds(seed: Any, n: int) -> list[int | None]:
    if seed is None:
        return [None] * n
    if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
        return [int(seed) + i for i in range(n)]
    if isinstance(seed, (list, tuple)) and len(seed) == n:
        return [None if s is None else int(s) for s in seed]
    raise ValueError(f"seed must be None, an integer (env i gets seed + i) or a list of {n} seeds, got {seed!r}")


def _checked_mask(mask: Any, n: int) -> np.ndarray:
    mask = np.asarray(mask)
    if mask.shape != (n,) or mask.dtype != np.bool_ or not mask.any():
        raise ValueError(f"options['reset_mask'] must be a ({n},) bool array with a True, got {mask!r}")
    return mask
