"""Gymnasium ids for every physics task of the suite: ``import tatl_mj.gym`` registers them.

>>> import gymnasium as gym
>>> import tatl_mj.gym  # noqa: F401  (registers tatl_mj/...-v0)
>>> env = gym.make("tatl_mj/BicycleBalance-v0", render_mode="rgb_array")
>>> observation, info = env.reset(seed=0)

Ids are ``tatl_mj/<Domain><Task>-v0`` (``GYM_IDS`` lists them, e.g.
``tatl_mj/CartpoleBalance-v0``, ``tatl_mj/PendulumSwingupFlipped-v0``). Each
wraps ``suite.load(domain, task)``:

- observation: the task's state vector, ``Box(-inf, inf, (d,), float64)``;
- action: the actuator value, ``Box(low, high, (1,), float64)`` with the
  actuator's limits (the paper's discrete action set is a subset:
  ``suite.action_set(domain)``);
- ``terminated``: an absorbing state (discount 0) or a diverged simulation
  (``info["diverged"]`` holds MuJoCo's message); ``truncated``: the task's time
  limit;
- ``reset(seed=s)`` reseeds the task's own random state, so the start state is a
  function of ``s``; ``render()`` draws the ``"tracking"`` camera.

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
VERSION = 0
PHYSICS_TASKS: tuple[tuple[str, str], ...] = tuple(
    (d, t) for d, t in suite.ALL_TASKS if not suite.describe(d, t).discrete
)
RENDER_MODES: tuple[str, ...] = ("rgb_array",)


def gym_id(domain: str, task: str) -> str:
    """``("pendulum", "swingup_flipped")`` -> ``"tatl_mj/PendulumSwingupFlipped-v0"``."""
    words = f"{domain}_{task}".split("_")
    return f"{NAMESPACE}/{''.join(w.capitalize() for w in words)}-v{VERSION}"


GYM_IDS: dict[str, tuple[str, str]] = {gym_id(d, t): (d, t) for d, t in PHYSICS_TASKS}


class TatlEnv(gymnasium.Env):
    """A tatl-mj physics task as a Gymnasium environment (see the module docstring)."""

    def __init__(
        self,
        domain: str,
        task: str,
        task_kwargs: dict[str, Any] | None = None,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 480,
        camera: str = "tracking",
    ) -> None:
        if (domain, task) not in PHYSICS_TASKS:
            raise ValueError(f"unknown physics task {domain}/{task}; valid: {[f'{d}/{t}' for d, t in PHYSICS_TASKS]}")
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise ValueError(f"render_mode must be None or one of {RENDER_MODES}, got {render_mode!r}")
        self._env = suite.load(domain, task, task_kwargs=task_kwargs)
        (size,) = self._env.observation_spec()["state"].shape
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(size,), dtype=np.float64)
        action = self._env.action_spec()
        self.action_space = spaces.Box(
            np.asarray(action.minimum, np.float64),
            np.asarray(action.maximum, np.float64),
            shape=action.shape,
            dtype=np.float64,
        )
        self.render_mode = render_mode
        self.metadata = {
            "render_modes": list(RENDER_MODES),
            "render_fps": int(round(1.0 / self._env.control_timestep())),
        }
        self._size = (height, width)
        self._camera = camera

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
        timestep = self._env.step(np.asarray(action, dtype=np.float64).reshape(self.action_space.shape))
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

    def _observation(self, timestep: Any) -> np.ndarray:
        return np.asarray(timestep.observation["state"], dtype=np.float64)


def register() -> list[str]:
    """Registers every id of ``GYM_IDS`` (again is harmless); returns them."""
    for env_id, (domain, task) in GYM_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point=TatlEnv, kwargs={"domain": domain, "task": task})
    return list(GYM_IDS)


register()
