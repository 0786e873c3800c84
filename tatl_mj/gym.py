"""Gymnasium ids for every physics task of the suite: ``import tatl_mj.gym`` registers them.

>>> import gymnasium as gym
>>> import tatl_mj.gym  # noqa: F401  (registers tatl_mj/...-v2)
>>> env = gym.make("tatl_mj/BicycleBalance-v2", render_mode="rgb_array")
>>> observation, info = env.reset(seed=0)
>>> envs = gym.make_vec("tatl_mj/BicycleBalance-v2", num_envs=64, vectorization_mode="vector_entry_point")

Ids are ``tatl_mj/<Domain><Task>-v2`` (``GYM_IDS`` lists them, e.g.
``tatl_mj/CartpoleBalance-v2``, ``tatl_mj/PendulumSwingupFlipped-v2``). Each
wraps ``suite.load(domain, task)``:

- observation: the task's state vector, ``Box(-OBSERVATION_BOUND,
  OBSERVATION_BOUND, (d,), float64)``: in effect any finite value (the states
  have no tighter guaranteed bounds; a diverged simulation ends with its last
  finite state). float64, the simulator's own numbers, so an observation is
  bit for bit the state ``suite.load`` and ``tatl_mj.sampling`` give (a policy
  network casts it to its own precision anyway);
- action: the actuator value as a fraction of its limit, ``Box(-1, 1, (1,),
  float32)`` (float32, as Stable-Baselines3 and most deep-RL code expect); ``a``
  applies ``a * high`` (the actuator limits are symmetric, e.g. +-20 N for the
  cart-pole; ``env.unwrapped.actuator_limit`` holds them). With
  ``gym.make(id, normalize_actions=False)`` the action is the actuator value
  itself, ``Box(-high, high)`` (Gymnasium's checker then advises a normalised
  space). The paper's discrete action set ``suite.action_set(domain)`` is
  ``{-1, 0, 1}`` normalised. An action of the wrong shape or not finite raises
  ``ValueError`` naming the space, one beyond it is clipped to it;
- ``terminated``: an absorbing state (discount 0) or a diverged simulation
  (``info["diverged"]`` holds MuJoCo's message); ``truncated``: the task's time
  limit, which is also ``max_episode_steps``: ``gym.make`` returns the env in a
  ``TimeLimit`` of the task's steps (``task_kwargs={"time_limit": s}``
  included), so ``env.spec.max_episode_steps`` reports it. ``gym.make``'s own
  ``max_episode_steps=`` can shorten an episode, not lengthen it past the
  task's limit;
- ``reset(seed=s)`` reseeds the task's own random state, so the start state is a
  function of ``s``; ``render()`` draws the camera the domain declares (the one
  ``tatl render`` uses, ``render.default_camera``: the bicycle from behind),
  or ``gym.make(id, camera=name)``'s. No GL library is loaded before the first
  ``render()`` (``tatl_mj.gl``), whatever the render mode.

``gym.make_vec(id, num_envs=N, vectorization_mode="vector_entry_point")`` steps
all N simulations in one batched MuJoCo call (``tatl_mj.vector``), each env's
transitions those of the single env with the same seed and actions.
``-v1`` ids stay registered, as they were (float64 actions, no
``max_episode_steps``), with a deprecation warning naming the ``-v2`` id
(docs/versions.md).

``gym.make(id, task_kwargs={...})`` passes task options (e.g. ``time_limit``) to
``suite.load``. Tasks that take action indices and have no MuJoCo model
(``suite.describe(...).discrete``) are not registered. Gymnasium is an optional dependency (the ``gym`` extra).
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from tatl_mj import suite

NAMESPACE = "tatl_mj"
# The ids' interface version (spaces, wrappers, vector entry point), not the tasks' dynamics.
# v2: float32 actions, TimeLimit of the task's steps, a vector entry point.
# v1: actions are fractions of the actuator limit, Box(-1, 1); v0 took actuator units.
VERSION = 2
DEPRECATED_VERSION = 1
ACTION_DTYPE = np.float32
PHYSICS_TASKS: tuple[tuple[str, str], ...] = tuple(
    (d, t) for d, t in suite.ALL_TASKS if not suite.describe(d, t).discrete
)
RENDER_MODES: tuple[str, ...] = ("rgb_array",)
# Observation bounds: finite (Gymnasium's checker flags infinite ones) and half the largest
# float64, so that sampling the space does not overflow; no state comes near it.
OBSERVATION_BOUND = float(np.finfo(np.float64).max) / 2


def gym_id(domain: str, task: str, version: int = VERSION) -> str:
    """``("pendulum", "swingup_flipped")`` -> ``"tatl_mj/PendulumSwingupFlipped-v2"``."""
    words = f"{domain}_{task}".split("_")
    return f"{NAMESPACE}/{''.join(w.capitalize() for w in words)}-v{version}"


GYM_IDS: dict[str, tuple[str, str]] = {gym_id(d, t): (d, t) for d, t in PHYSICS_TASKS}


def episode_steps(env: Any, domain: str, task: str, task_kwargs: dict[str, Any] | None) -> int | None:
    """Control steps after which the task's time limit ends an episode of ``env`` (its
    ``suite.load``), counted as dm_control does; None without a limit."""
    limit = suite.time_limit(domain, task, task_kwargs)
    if limit == math.inf:
        return None
    # dm_control: the episode ends once step_count >= time_limit / control_timestep.
    return math.ceil(limit / env.control_timestep())


def action_space(
    actuator_limit: np.ndarray, normalize_actions: bool, dtype: Any = ACTION_DTYPE
) -> tuple[spaces.Box, np.ndarray]:
    """The action space and the factor from an action to the actuator's units."""
    bound = np.ones(actuator_limit.shape) if normalize_actions else actuator_limit
    scale = actuator_limit if normalize_actions else np.ones(actuator_limit.shape)
    bound = bound.astype(dtype)  # the limits are round numbers, exact in float32
    return spaces.Box(-bound, bound, shape=actuator_limit.shape, dtype=dtype), scale


def observation_space(size: int) -> spaces.Box:
    return spaces.Box(-OBSERVATION_BOUND, OBSERVATION_BOUND, shape=(size,), dtype=np.float64)


def actuator_limit(env: Any, name: str) -> np.ndarray:
    """``env``'s (a ``suite.load``) actuator limits, checked symmetric about 0."""
    action = env.action_spec()
    low = np.broadcast_to(np.asarray(action.minimum, np.float64), action.shape)
    high = np.broadcast_to(np.asarray(action.maximum, np.float64), action.shape)
    if not np.array_equal(low, -high) or not np.all(high > 0):
        raise ValueError(f"{name}: actuator limits {low} .. {high} are not symmetric about 0")
    return high.copy()


def check_physics_task(domain: str, task: str) -> None:
    if (domain, task) not in PHYSICS_TASKS:
        raise ValueError(f"unknown physics task {domain}/{task}; valid: {[f'{d}/{t}' for d, t in PHYSICS_TASKS]}")


def check_render_mode(render_mode: str | None) -> None:
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise ValueError(f"render_mode must be None or one of {RENDER_MODES}, got {render_mode!r}")


def default_camera(domain: str, camera: str | None) -> str:
    """The camera frames are drawn from: ``camera``, else the one the domain declares."""
    return getattr(suite.DOMAINS[domain], "CAMERA", "tracking") if camera is None else camera


class TatlEnv(gymnasium.Env):
    """A tatl-mj physics task as a Gymnasium environment (see the module docstring)."""

    # gymnasium.make reads the render modes from the class; render_fps is the
    # task's control rate, set on each instance.
    metadata: dict[str, Any] = {"render_modes": list(RENDER_MODES), "render_fps": None}

    def __init__(
        self,
        domain: str,
        task: str,
        task_kwargs: dict[str, Any] | None = None,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 480,
        camera: str | None = None,
        normalize_actions: bool = True,
        action_dtype: Any = ACTION_DTYPE,
        context_in_observation: bool = False,
    ) -> None:
        check_physics_task(domain, task)
        check_render_mode(render_mode)
        if not isinstance(context_in_observation, bool):
            raise ValueError(f"context_in_observation must be True or False, got {context_in_observation!r}")
        self._domain, self._task_name, self._task_kwargs = domain, task, dict(task_kwargs or {})
        self._env = suite.load(domain, task, task_kwargs=task_kwargs)
        # The context of the episodes from the last reset that gave one (None: task_kwargs' own).
        self._context: dict[str, float] | None = None
        self._context_in_observation = context_in_observation
        self._context_size = len(suite.context_spec(domain, task).keys) if context_in_observation else 0
        (size,) = self._env.observation_spec()["state"].shape
        self.observation_space = observation_space(size + self._context_size)
        self._high = actuator_limit(self._env, f"{domain}/{task}")
        self.action_space, self._scale = action_space(self._high, normalize_actions, action_dtype)
        self.render_mode = render_mode
        self.metadata = {**type(self).metadata, "render_fps": int(round(1.0 / self._env.control_timestep()))}
        self._size = (height, width)
        self._camera = default_camera(domain, camera)
        self.max_episode_steps = episode_steps(self._env, domain, task, task_kwargs)

    @property
    def actuator_limit(self) -> np.ndarray:
        """The actuator's limits, (1,): the largest actuator value (an action of 1 when normalised)."""
        return self._high.copy()

    @property
    def dm_environment(self) -> Any:
        """The wrapped dm_env environment (``suite.load``'s)."""
        return self._env

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Starts an episode; ``seed`` reseeds the task's random state. ``options={"context": c}``
        gives this episode and the next ones the context ``c`` (``suite.check_context``): the task
        is built again with it, its random state carried over."""
        super().reset(seed=seed)
        options = dict(options or {})
        if "context" in options:
            self._set_context(options.pop("context"))
        if options:
            raise ValueError(f"unknown reset options {sorted(options)}; valid: ['context']")
        if seed is not None:
            self._env.task.random.seed(seed)
        timestep = self._env.reset()
        return self._observation(timestep), self._info({})

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        timestep = self._env.step(actuator_values(action, self.action_space, self._scale))
        info: dict[str, Any] = {}
        diverged = getattr(self._env, "diverged", None)
        if diverged:
            info["diverged"] = diverged
        terminated = bool(timestep.last() and timestep.discount == 0)
        truncated = bool(timestep.last() and not terminated)
        return self._observation(timestep), float(timestep.reward or 0.0), terminated, truncated, self._info(info)

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            return None
        height, width = self._size
        return self._env.physics.render(height=height, width=width, camera_id=self._camera)

    def close(self) -> None:
        self._env.physics.free_canvases()

    @property
    def context(self) -> dict[str, float]:
        """The values of every context key in the current episode (``suite.check_context``)."""
        if self._context is None:
            self._context = suite.check_context(self._domain, self._task_name, {}, self._task_kwargs)
        return dict(self._context)

    def _set_context(self, context: Any) -> None:
        """Builds the task again with ``context`` (checked first), on the same random state."""
        values = suite.check_context(self._domain, self._task_name, context, self._task_kwargs, "reset context")
        kwargs = suite.task_kwargs_with_context(self._domain, self._task_name, self._task_kwargs, values)
        random = self._env.task.random  # the stream goes on, as in an env that was never rebuilt
        self._env.physics.free_canvases()
        self._env = suite.load(self._domain, self._task_name, task_kwargs={**kwargs, "random": random})
        self._context = values

    def _info(self, info: dict[str, Any]) -> dict[str, Any]:
        if self._context is not None or self._context_in_observation:
            info["context"] = self.context
        return info

    def _observation(self, timestep: Any) -> np.ndarray:
        # A copy: a diverged step returns the last observation object again.
        state = np.array(timestep.observation["state"], dtype=np.float64)
        if not self._context_in_observation:
            return state
        return np.concatenate([state, np.fromiter(self.context.values(), np.float64, self._context_size)])


def actuator_values(action: Any, space: spaces.Box, scale: np.ndarray) -> np.ndarray:
    """``action`` checked against ``space`` (a vector env's batched one, or a single env's) and
    scaled to the actuator's units.

    Raises ValueError naming the space for a wrong shape or a value that is not
    finite; beyond the space is clipped to it, as the actuator's control range
    would (policies with unbounded noise, e.g. Gaussian, step past it routinely).
    """
    try:
        value = np.asarray(action, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"action must be an array in the action space {space}, got {action!r}") from None
    if value.shape != space.shape:
        raise ValueError(f"action must have shape {space.shape} (the action space {space}), got shape {value.shape}")
    if not np.all(np.isfinite(value)):
        raise ValueError(f"action {value.tolist()} is not finite (the action space is {space})")
    return np.clip(value, space.low, space.high) * scale


def action_scale(space: spaces.Box, limit: np.ndarray) -> np.ndarray:
    """The factor from an action of ``space`` to actuator units, where ``space`` is one of the
    action spaces an id of a task with actuator limits ``limit`` has (normalised or not, any
    dtype); ValueError naming both otherwise (an agent trained on another task)."""
    for normalize in (True, False):
        expected, scale = action_space(limit, normalize, space.dtype)
        if expected.shape == space.shape and np.array_equal(expected.low, space.low):
            if np.array_equal(expected.high, space.high):
                return scale
    raise ValueError(
        f"action space {space} is neither of this task's: {action_space(limit, True)[0]} (normalised) "
        f"or {action_space(limit, False)[0]} (actuator units)"
    )


def batch_actuator_values(actions: Any, space: spaces.Box, scale: np.ndarray) -> np.ndarray:
    """A batch of actions of ``space`` (N, *shape) as actuator values, each as :meth:`TatlEnv.step`
    applies it (:func:`actuator_values`: checked, clipped to the space, scaled)."""
    actions = np.asarray(actions)
    n = actions.shape[0] if actions.ndim else 0  # a shape of no batch is refused by the check
    batched = spaces.Box(
        np.broadcast_to(space.low, (n, *space.shape)),
        np.broadcast_to(space.high, (n, *space.shape)),
        dtype=space.dtype,  # type: ignore[arg-type]
    )
    return actuator_values(actions, batched, scale)


def make_env(domain: str, task: str, task_kwargs: dict[str, Any] | None = None, **kwargs: Any) -> gymnasium.Env:
    """The ``-v2`` entry point: a :class:`TatlEnv` in a ``TimeLimit`` of the task's steps.

    The time limit comes from the task (and ``task_kwargs["time_limit"]``), so
    the registry holds no ``max_episode_steps`` of its own: ``gym.make`` would wrap
    a second, fixed one around this, which would cut a longer limit short.
    """
    env = TatlEnv(domain, task, task_kwargs=task_kwargs, **kwargs)
    if env.max_episode_steps is None:
        return env
    return gymnasium.wrappers.TimeLimit(env, env.max_episode_steps)


def make_v1_env(domain: str, task: str, **kwargs: Any) -> gymnasium.Env:
    """The ``-v1`` entry point: the env as it was (float64 actions, no TimeLimit), with a notice."""
    warnings.warn(
        f"{gym_id(domain, task, DEPRECATED_VERSION)} is deprecated: use {gym_id(domain, task)}, whose actions "
        "are float32, whose episodes end in a TimeLimit of the task's steps (env.spec.max_episode_steps) and "
        "which has a batched vector env; the dynamics are the same (docs/versions.md)",
        DeprecationWarning,
        stacklevel=2,
    )
    return TatlEnv(domain, task, action_dtype=np.float64, **kwargs)


def register() -> list[str]:
    """Registers every id of ``GYM_IDS`` and its deprecated ``-v1`` (again is harmless); returns the ``-v2`` ids."""
    for env_id, (domain, task) in GYM_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(
                id=env_id,
                entry_point=make_env,
                vector_entry_point="tatl_mj.vector:TatlVectorEnv",
                kwargs={"domain": domain, "task": task},
            )
        old = gym_id(domain, task, DEPRECATED_VERSION)
        if old not in gymnasium.registry:
            gymnasium.register(id=old, entry_point=make_v1_env, kwargs={"domain": domain, "task": task})
    return list(GYM_IDS)


register()
