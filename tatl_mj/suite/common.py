"""What every tatl-mj domain shares: model files, parameter checks, the environment.

A physics domain is a module beside this one with
- a ``Physics`` subclass of :class:`StatePhysics` (named getters, ``state_vector``),
- a ``Task`` (usually a :class:`StateTask`),
- ``ACTIONS``: the paper's discrete action set; ``env.step(ACTIONS[i])`` is valid,
- ``TASKS``: ``{task_name: factory}``; a factory takes ``time_limit``, ``random``,
  ``environment_kwargs`` and the task's own keyword arguments.
"""

from __future__ import annotations

import collections
import dataclasses
import functools
import math
from pathlib import Path
from typing import Any

import dm_env
import numpy as np
from dm_control.mujoco import engine, wrapper
from dm_control.rl import control
from dm_control.suite import base

from tatl_mj import gl

# tatl_mj/assets links to the repository's assets/ (and is a real folder in a wheel).
MJCF_DIR = Path(__file__).resolve().parents[1] / "assets" / "mjcf"
_COMMON_INCLUDES = ("common/materials.xml", "common/skybox.xml", "common/visual.xml")


def read_model(filename: str) -> tuple[str, dict[str, bytes]]:
    """Returns an MJCF file's text and the shared include files it may use."""
    path = MJCF_DIR / filename
    if not path.is_file():
        raise FileNotFoundError(f"MJCF model {filename!r} not found in {MJCF_DIR}")
    assets = {name: (MJCF_DIR / name).read_bytes() for name in _COMMON_INCLUDES}
    return path.read_text(), assets


@functools.lru_cache(maxsize=32)
def _compiled(xml: str, assets: tuple[tuple[str, bytes], ...]) -> wrapper.MjModel:
    return wrapper.MjModel.from_xml_string(xml, assets=dict(assets))


def compile_physics(physics_type: type[engine.Physics], xml: str, assets: dict[str, bytes]) -> Any:
    """``physics_type.from_xml_string(xml, assets)``, each distinct model compiled once.

    Compiling is most of the cost of a ``suite.load``, and the sampler loads an
    environment per call. Every physics
    gets its own copy of the model, so runtime model edits stay its own.
    """
    return physics_type.from_model(_compiled(xml, tuple(sorted(assets.items()))).copy())


def parse_model(filename: str, params: Any, params_type: type) -> tuple[Any, dict[str, bytes]]:
    """An MJCF file as an ElementTree root to write ``params`` into, and its includes.

    Raises ValueError when ``params`` is not a ``params_type``.
    """
    import xml.etree.ElementTree as ET

    if not isinstance(params, params_type):
        raise ValueError(f"params must be a {params_type.__name__}, got {type(params).__name__}")
    xml, assets = read_model(filename)
    return ET.fromstring(xml), assets


# --- Physical parameters ------------------------------------------------------


def positive(default: float, doc: str = "") -> Any:
    """A dataclass field that must be a finite number > 0."""
    return dataclasses.field(default=default, metadata={"bound": "positive", "doc": doc})


def nonnegative(default: float, doc: str = "") -> Any:
    """A dataclass field that must be a finite number >= 0."""
    return dataclasses.field(default=default, metadata={"bound": "nonnegative", "doc": doc})


def is_real(value: Any) -> bool:
    """A real number: int, float or a numpy scalar of either, not a bool."""
    return not isinstance(value, (bool, np.bool_)) and isinstance(value, (int, float, np.integer, np.floating))


def real(value: Any, name: str) -> float:
    """``value`` as a float; raises ValueError naming ``name`` unless it is a real number (not "1", None, True)."""
    if not is_real(value):
        raise ValueError(f"{name} must be a number, got {value!r} ({type(value).__name__})")
    return float(value)


def check_params(params: Any) -> None:
    """Raises ValueError naming the first field that is not physical.

    Every field declared ``float`` (or made with :func:`positive` /
    :func:`nonnegative`) must be a finite real number, not a string or a bool;
    bounded fields must also respect their bound. Call it from
    ``__post_init__`` of a frozen parameter dataclass.
    """
    cls = type(params).__name__
    for field in dataclasses.fields(params):
        value = getattr(params, field.name)
        numeric = field.type in ("float", float) or "bound" in field.metadata
        if not numeric:
            continue
        if not is_real(value):
            raise ValueError(f"{cls}.{field.name} must be a number, got {value!r} ({type(value).__name__})")
        if not math.isfinite(value):
            raise ValueError(f"{cls}.{field.name} must be a finite number, got {value!r}")
        bound = field.metadata.get("bound")
        if bound == "positive" and value <= 0:
            raise ValueError(f"{cls}.{field.name} must be > 0, got {value!r}")
        if bound == "nonnegative" and value < 0:
            raise ValueError(f"{cls}.{field.name} must be >= 0, got {value!r}")


# --- Physics and task ---------------------------------------------------------


class StatePhysics(engine.Physics):
    """A Physics that speaks the paper's state vector.

    ``state_vector()`` returns the paper's state (float64, domain order) and
    ``set_state_vector(s)`` puts the simulator in that state, so that a transfer
    method can ask what the system does from a given state (Algorithm 1).

    Both go through the vectorised pair ``states_from`` / ``qpos_qvel_from``, which
    the fast sampler (``tatl_mj.sampling``) applies to whole ``mujoco.rollout``
    batches: one formula serves the environment and the sampler.
    """

    STATE_SIZE: int = 0

    def states_from(self, qpos: np.ndarray, qvel: np.ndarray) -> np.ndarray:
        """(N, nq), (N, nv) -> (N, STATE_SIZE) paper states."""
        raise NotImplementedError

    def qpos_qvel_from(self, states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, STATE_SIZE) paper states -> (N, nq), (N, nv). Inverse of ``states_from``."""
        raise NotImplementedError

    def after_reset(self) -> None:
        # dm_control's own after_reset runs forward() with actuation disabled,
        # leaving actuator_velocity stale (0): a velocity servo (the bicycle's
        # speed servo) would then kick the system on the next step, and
        # mujoco.rollout, which computes it afresh, would not replay the episode.
        self.forward()

    def render(self, height: int = 240, width: int = 320, camera_id: int | str = -1, **options: Any) -> np.ndarray:
        """An RGB frame ``(height, width, 3)`` uint8 from camera ``camera_id`` (an id or a
        name; -1 is the free camera), drawn on tatl-mj's own GL context (``tatl_mj.gl``,
        whose backend is chosen and loaded at the first frame a process draws).

        dm_control's own renderer stays off (``gl.import_simulators``), and with it its
        other options (depth, segmentation, overlays, scene options).
        """
        if options:
            raise ValueError(
                f"physics.render takes height, width and camera_id; got {sorted(options)}, "
                "dm_control options tatl-mj does not draw"
            )
        camera = self.model.name2id(camera_id, "camera") if isinstance(camera_id, str) else int(camera_id)
        canvases = self.__dict__.setdefault("_canvases", {})
        canvas = canvases.get((height, width))
        if canvas is None or canvas.model is not self.model.ptr:  # a reloaded model gets a new one
            canvas = canvases[height, width] = gl.Canvas(self.model.ptr, height, width)
        return canvas.draw(self.data.ptr, camera)

    def free_canvases(self) -> None:
        """Frees the GL contexts ``render`` made (a later ``render`` makes new ones)."""
        for canvas in self.__dict__.pop("_canvases", {}).values():
            canvas.close()

    def free(self) -> None:
        self.free_canvases()
        super().free()

    def state_vector(self) -> np.ndarray:
        return self.states_from(self.data.qpos[None], self.data.qvel[None])[0]

    def set_state_vector(self, state: np.ndarray) -> None:
        s = as_state(state, self.STATE_SIZE, type(self).__module__)
        qpos, qvel = self.qpos_qvel_from(s[None])
        with self.reset_context():
            self.data.qpos[:] = qpos[0]
            self.data.qvel[:] = qvel[0]


def check_action(action: Any, spec: Any) -> np.ndarray:
    """An action checked against its ``action_spec()``; returns it as float64 of the spec's shape.

    Policy: the shape must be the spec's (a plain number is also taken for a
    spec of shape (1,)), and every value finite; anything else raises
    ValueError. Finite values outside the spec's bounds are not an error:
    MuJoCo clips them to the actuator's ``ctrlrange``, as in dm_control.
    """
    try:
        a = np.asarray(action, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"action must be numbers of shape {spec.shape}, got {action!r}") from None
    if a.shape != spec.shape and not (a.ndim == 0 and spec.shape == (1,)):
        raise ValueError(f"action must have shape {spec.shape} (the action_spec), got shape {a.shape}: {action!r}")
    if not np.isfinite(a).all():
        raise ValueError(f"action must be finite, got {action!r}")
    return a.reshape(spec.shape)


def check_time_limit(time_limit: Any) -> float:
    """A task's time limit in seconds: a number > 0 (``inf`` for none); raises ValueError otherwise."""
    value = real(time_limit, "time_limit")
    if math.isnan(value) or value <= 0:
        raise ValueError(f"time_limit must be a number of seconds > 0 (or inf), got {time_limit!r}")
    return value


def as_state(state: Any, size: int, domain: str) -> np.ndarray:
    """Checks a state vector's shape and finiteness; returns it as float64."""
    s = np.asarray(state, dtype=np.float64)
    if s.shape != (size,):
        raise ValueError(f"{domain} state must have shape ({size},), got {s.shape}")
    if not np.all(np.isfinite(s)):
        raise ValueError(f"{domain} state must be finite, got {s}")
    return s


class StateTask(base.Task):
    """A task whose observation is the paper's state: ``{"state": float64 array}``.

    Reward, termination and the mapping from an action to the full control
    vector are vectorised hooks, so that ``tatl_mj.sampling`` reproduces the
    task exactly over ``mujoco.rollout`` batches:

    - ``batch_reward(states) -> (N,)``: reward after a step that ends in ``states``;
    - ``batch_absorbing(states) -> (N,) bool``: the episode ends with discount 0
      (a failure or the goal);
    - ``controls(action_values, random) -> (N, nu)``: the full ``ctrl`` vector for
      actions ``(N, action_dim)`` (adds e.g. servo set-points or rider noise);
      any noise is drawn row after row, so that one call on stacked rows equals
      successive calls on their parts (the sampler draws a block of an
      episode's steps in one call). ``random`` is the task's RandomState in the
      environment and a Generator in the sampler: draw with methods both have
      (``uniform``, ``normal``);
    - ``start_configurations(physics, n) -> (n, nq), (n, nv)``: where ``n``
      successive episodes start, drawn from ``self.random`` exactly as ``n``
      resets would draw them; ``initialize_episode`` is this with ``n = 1``,
      and the sampler starts many episodes with one call;
    - ``rollout_compatible``: False when the model itself changes during an
      episode (the time-varying pendulum), so the sampler must step the env;
    - ``model_for_step(physics, step)``: with ``rollout_compatible`` False, an
      optional method that edits ``physics``'s model into the one an episode's
      control step ``step`` (0, 1, ...) runs on, when that model depends on the
      step alone (the time-varying pendulum's schedule); ``before_step`` calls
      it. One-step queries (each an episode's step 0) are then batched on that
      model, and evaluation episodes, which all start together, run in lockstep
      on one model edited per step;
    - ``control_noise``: whether ``controls`` draws from ``random`` (the bicycle's
      rider). Without noise the sampler maps only the actions a call takes, with
      ``random=None``; by default a task that overrides ``controls`` is taken to
      draw noise, and may say otherwise.
    """

    rollout_compatible: bool = True

    @property
    def control_noise(self) -> bool:
        return type(self).controls is not StateTask.controls

    def start_configurations(self, physics: StatePhysics, n: int) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def initialize_episode(self, physics: StatePhysics) -> None:
        qpos, qvel = self.start_configurations(physics, 1)
        # dm_control already runs this inside physics.reset_context().
        physics.data.qpos[:] = qpos[0]
        physics.data.qvel[:] = qvel[0]
        super().initialize_episode(physics)

    # The state after the step being taken: reward, observation and termination
    # of one env.step all read it, so it is computed once (a third of dm_control's
    # loop on mountain car). Environment.step forgets it when the step returns.
    _step_state: np.ndarray | None = None

    def state(self, physics: StatePhysics) -> np.ndarray:
        """``physics.state_vector()``, computed once per ``env.step``."""
        return physics.state_vector() if self._step_state is None else self._step_state

    def after_step(self, physics: StatePhysics) -> None:
        super().after_step(physics)
        self._step_state = physics.state_vector()

    def forget_step_state(self) -> None:
        self._step_state = None

    def get_observation(self, physics: StatePhysics) -> collections.OrderedDict:
        return collections.OrderedDict(state=self.state(physics))

    def batch_reward(self, states: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def batch_absorbing(self, states: np.ndarray) -> np.ndarray:
        return np.zeros(len(states), dtype=bool)

    def controls(self, action_values: np.ndarray, random: np.random.RandomState | np.random.Generator) -> np.ndarray:
        return np.asarray(action_values, dtype=np.float64)

    def before_step(self, action: Any, physics: StatePhysics) -> None:
        spec = getattr(self, "_checked_action_spec", None)
        if spec is None:  # the model's actuators never change, so build the spec once
            spec = self._checked_action_spec = self.action_spec(physics)
        action = check_action(action, spec)
        physics.set_control(self.controls(action.reshape(1, -1), self.random)[0])

    def get_reward(self, physics: StatePhysics) -> float:
        return float(self.batch_reward(self.state(physics)[None])[0])

    def get_termination(self, physics: StatePhysics) -> float | None:
        return 0.0 if self.batch_absorbing(self.state(physics)[None])[0] else None


class Environment(control.Environment):
    """dm_control's Environment, except that a diverging simulation ends the episode.

    When MuJoCo raises a warning (e.g. ``mjWARN_BADQACC``) during a step, the
    episode ends with ``discount=0``, reward 0 and the last finite observation;
    ``diverged`` then holds MuJoCo's message, so the failure is never silent and
    never returns NaN. The next ``step`` starts a new episode, as after any end.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        if "time_limit" in kwargs:  # every factory passes it by keyword
            kwargs["time_limit"] = check_time_limit(kwargs["time_limit"])
        super().__init__(*args, **kwargs)
        self.diverged: str | None = None
        self._last_observation: Any = None
        self._must_reset = False

    def reset(self) -> dm_env.TimeStep:
        self.diverged = None
        self._must_reset = False
        timestep = super().reset()
        self._last_observation = timestep.observation
        return timestep

    def step(self, action: Any) -> dm_env.TimeStep:
        if self._must_reset:
            return self.reset()
        try:
            timestep = super().step(action)
        except control.PhysicsError as error:
            self.diverged = str(error)
            self._must_reset = True
            return dm_env.termination(reward=0.0, observation=self._last_observation)
        finally:
            forget = getattr(self.task, "forget_step_state", None)
            if forget is not None:
                forget()
        self._last_observation = timestep.observation
        return timestep
