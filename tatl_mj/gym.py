"""Gymnasium ids for every physics task of the suite: ``import tatl_mj.gym`` registers them.

>>> import gymnasium as gym
>>> import tatl_mj.gym  # noqa: F401  (registers tatl_mj/...-v1)
>>> env = gym.make("tatl_mj/BicycleBalance-v1", render_mode="rgb_array")
>>> observation, info = env.reset(seed=0)

Ids are ``tatl_mj/<Domain><Task>-v1`` (``GYM_IDS`` lists them, e.g.
``tatl_mj/CartpoleBalance-v1``, ``tatl_mj/PendulumSwingupFlipped-v1``). Each
wraps ``suite.load(domain, task)``:

- observation: the task's state vector, ``Box(-OBSERVATION_BOUND,
  OBSERVATION_BOUND, (d,), float64)``: in effect any finite value (the states
  have no tighter guaranteed bounds; a diverged simulation ends with its last
  finite state);
- action: the actuator value as a fraction of its limit, ``Box(-1, 1, (1,),
  float64)``; ``a`` applies ``a * high`` (the actuator limits are symmetric, e.g.
  +-20 N for the cart-pole; ``env.unwrapped.actuator_limit`` holds them). With
  ``gym.make(id, normalize_actions=False)`` the action is the actuator value
  itself, ``Box(-high, high)`` (Gymnasium's checker then advises a normalised
  space). The paper's discrete action set ``suite.action_set(domain)`` is
  ``{-1, 0, 1}`` normalised. An action of the wrong shape or outside the space
  raises ``ValueError`` naming the space, one beyond it is clipped to it;
- ``terminated``: an absorbing state (discount 0) or a diverged simulation
  (``info["diverged"]`` holds MuJoCo's message); ``truncated``: the task's time
  limit;
- ``reset(seed=s)`` reseeds the task's own random state, so the start state is a
  function of ``s``; ``render()`` draws the camera the domain declares (the one
  ``tatl render`` uses, ``render.default_camera``: the bicycle from behind),
  or ``gym.make(id, camera=name)``'s.

``gym.make(id, task_kwargs={...})`` passes task options (e.g. ``time_limit``) to
``suite.load``. Tasks that take action indices and have no MuJoCo model
(``suite.describe(...).discrete``) are not registered. Gymnasium is an optional dependency (the ``test`` extra).
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from tatl_mj import suite

NAMESPACE = "tatl_mj"
# v1: actions are fractions of the actuator limit, Box(-1, 1); v0 took actuator units.
VERSION = 1
PHYSICS_TASKS: tuple[tuple[str, str], ...] = tuple(
    (d, t) for d, t in suite.ALL_TASKS if not suite.describe(d, t).discrete
)
RENDER_MODES: tuple[str, ...] = ("rgb_array",)
# Observation bounds: finite (Gymnasium's checker flags infinite ones) and half the largest
# float64, so that sampling the space does not overflow; no state comes near it.
OBSERVATION_BOUND = float(np.finfo(np.float64).max) / 2


def gym_id(domain: str, task: str) -> str:
    """``("pendulum", "swingup_flipped")`` -> ``"tatl_mj/PendulumSwingupFlipped-v1"``."""
    words = f"{domain}_{task}".split("_")
    return f"{NAMESPACE}/{''.join(w.capitalize() for w in words)}-v{VERSION}"


GYM_IDS: dict[str, tuple[str, str]] = {gym_id(d, t): (d, t) for d, t in PHYSICS_TASKS}


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
    ) -> None:
        if (domain, task) not in PHYSICS_TASKS:
            raise ValueError(f"unknown physics task {domain}/{task}; valid: {[f'{d}/{t}' for d, t in PHYSICS_TASKS]}")
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise ValueError(f"render_mode must be None or one of {RENDER_MODES}, got {render_mode!r}")
        self._env = suite.load(domain, task, task_kwargs=task_kwargs)
        (size,) = self._env.observation_spec()["state"].shape
        self.observation_space = spaces.Box(-OBSERVATION_BOUND, OBSERVATION_BOUND, shape=(size,), dtype=np.float64)
        action = self._env.action_spec()
        low = np.broadcast_to(np.asarray(action.minimum, np.float64), action.shape)
        high = np.broadcast_to(np.asarray(action.maximum, np.float64), action.shape)
        if not np.array_equal(low, -high) or not np.all(high > 0):
            raise ValueError(f"{domain}/{task}: actuator limits {low} .. {high} are not symmetric about 0")
        self._high = high.copy()
        self._scale = self._high if normalize_actions else np.ones(action.shape)
        bound = np.ones(action.shape) if normalize_actions else high
        self.action_space = spaces.Box(-bound, bound, shape=action.shape, dtype=np.float64)
        self.render_mode = render_mode
        self.metadata = {**type(self).metadata, "render_fps": int(round(1.0 / self._env.control_timestep()))}
        self._size = (height, width)
        self._camera = getattr(suite.DOMAINS[domain], "CAMERA", "tracking") if camera is None else camera

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
        super().reset(seed=seed)
        if seed is not None:
            self._env.task.random.seed(seed)
        timestep = self._env.reset()
        return self._observation(timestep), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        timestep = self._env.step(self._actuator_value(action))
        info: dict[str, Any] = {}
        diverged = getattr(self._env, "diverged", None)
        if diverged:
            info["diverged"] = diverged
        terminated = bool(timestep.last() and timestep.discount == 0)
        truncated = bool(timestep.last() and not terminated)
        return self._observation(timestep), float(timestep.reward or 0.0), terminated, truncated, info

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            return None
        height, width = self._size
        return self._env.physics.render(height=height, width=width, camera_id=self._camera)

    def _actuator_value(self, action: Any) -> np.ndarray:
        """``action`` checked against the action space and scaled to the actuator's units."""
        space = self.action_space
        try:
            value = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"action must be an array in the action space {space}, got {action!r}") from None
        if value.shape != space.shape:
            raise ValueError(
                f"action must have shape {space.shape} (the action space {space}), got shape {value.shape}"
            )
        if not np.all(np.isfinite(value)):
            raise ValueError(f"action {value.tolist()} is not finite (the action space is {space})")
        # Beyond the space is clipped, as the actuator's control range would (policies with
        # unbounded noise, e.g. Gaussian, step past it routinely).
        return np.clip(value, space.low, space.high) * self._scale

    def _observation(self, timestep: Any) -> np.ndarray:
        return np.asarray(timestep.observation["state"], dtype=np.float64)


def register() -> list[str]:
    """Registers every id of ``GYM_IDS`` (again is harmless); returns them."""
    for env_id, (domain, task) in GYM_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point=TatlEnv, kwargs={"domain": domain, "task": task})
    return list(GYM_IDS)


register()
