"""Pendulum swing-up: an under-powered torque swings a point-like mass up and holds it.

The paper's inverted pendulum (IP) in three variants: the plain task, the
non-stationary target whose length and mass change every step, and the
negative-transfer target whose control acts with the opposite sign.

=================  ==========================================================
State              ``[theta, theta_dot]`` (float64)
                   theta: angle from upright (rad), wrapped to [-pi, pi),
                   positive when the rod leans towards +x;
                   theta_dot: angular velocity (rad/s), not limited.
Actions            ``ACTIONS = [[-4], [0], [4]]``: torque at the hinge (N m,
                   positive drives theta up). Any torque in +-``max_torque``
                   is accepted; larger values are clipped by MuJoCo.
                   ``swingup_flipped``: the same numbers act with the
                   opposite sign (actuator gear -1).
Reward             ``r = -10 theta^2 - 5 theta_dot^2`` after each step (the
                   paper's), 0 at best, about -99 hanging at rest.
Start state        hanging down: theta = pi + U(-0.05, 0.05),
                   theta_dot = U(-0.05, 0.05), from the task's ``random``.
Episode end        never absorbing; time limit (default 10 s = 200 steps).
Timing             control step 0.05 s; physics step 0.01 s (RK4).
Parameters         :class:`PendulumParams`: mass 1 kg, length 1 m, max_torque
                   4 N m (the full torque cannot hold the pendulum out
                   beyond 24 degrees from hanging, m g L = 9.81 N m; the
                   ratio 0.4 is Gymnasium Pendulum's. With 2 N m, FQI did not
                   learn to swing up in our measurements, see README),
                   gravity 9.81 m/s^2. The tip is a solid sphere of radius
                   0.05 m (inertia 2/5 m r^2 about its centre); the rod is
                   massless.
Time-varying       ``swingup_timevarying``: during control step i (i = 0 at
                   reset) L_i = L0 + 0.5 cos(pi i / 50) and
                   M_i = M0 + 0.5 cos(pi i / 50), L0 = length, M0 = mass
                   (1 and 1: the paper's). The model is edited in place
                   before each step; the state carries over unchanged.
=================  ==========================================================

Equation: ``(m L^2 + I) theta_dd = m g L sin(theta) + gear * u``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Mapping
from typing import Any

import mujoco
import numpy as np

from tatl_mj.description import TaskDescription
from tatl_mj.suite import common
from tatl_mj.suite.contexts import ContextKey, ContextSpec

CONTROL_TIMESTEP = 0.05  # s
DEFAULT_TIME_LIMIT = 10.0  # s, 200 control steps
TIP_RADIUS = 0.05  # m; fixed, so the tip inertia is 2/5 m r^2 for every mass
START_HALF_WIDTH = 0.05  # rad and rad/s around hanging at rest
# The camera clips film from (tatl_mj.render): fixed, side-on, the whole swing in view.
CAMERA = "tracking"
SCHEDULE_AMPLITUDE = 0.5  # m and kg
SCHEDULE_PERIOD_STEPS = 100  # cos(pi i / 50) repeats every 100 control steps

ACTIONS = np.array([[-4.0], [0.0], [4.0]])
DYNAMICS_VERSION = 1  # of every task here; docs/versions.md says when it is bumped


@dataclasses.dataclass(frozen=True)
class PendulumParams:
    """Physical parameters of the pendulum; non-physical values raise ValueError."""

    mass: float = common.positive(1.0, "tip mass (kg)")
    length: float = common.positive(1.0, "hinge to tip centre (m)")
    max_torque: float = common.positive(4.0, "largest torque the actuator applies (N m)")
    gravity: float = common.positive(9.81, "gravitational acceleration (m/s^2)")

    def __post_init__(self) -> None:
        common.check_params(self)


def timevarying_schedule(
    step: int, params: PendulumParams | None = None, amplitude: float = SCHEDULE_AMPLITUDE
) -> tuple[float, float]:
    """(length m, mass kg) during control step ``step`` of ``swingup_timevarying``."""
    params = params or PendulumParams()
    wave = amplitude * math.cos(math.pi * step / (SCHEDULE_PERIOD_STEPS / 2))
    return params.length + wave, params.mass + wave


def wrap_angle(theta: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-pi, pi)."""
    return np.mod(np.asarray(theta, np.float64) + np.pi, 2.0 * np.pi) - np.pi


def write_pendulum(field: Callable[[str], np.ndarray], ids: Any, rows: Any, lengths: Any, masses: Any) -> None:
    """Writes pendulums of ``lengths`` (m) and ``masses`` (kg) into rows ``rows`` of model fields.

    ``field(name)`` is a model field with a leading axis of rows: one model's as one
    row, or a ``mujoco.batch.Batch``'s per-simulation fields. ``ids`` are
    :meth:`Physics.pendulum_ids`. Writes the mass properties and the geometry;
    the caller then runs ``mj_setConst`` (a batch's ``set_const``) for the
    derived fields. The same numbers as :meth:`Physics.set_pendulum` writes, in
    the same operations.
    """
    pole, rod, tip = ids
    lengths, masses = np.asarray(lengths, np.float64), np.asarray(masses, np.float64)
    half = lengths / 2.0
    rod_radius = field("geom_size")[rows, rod, 0]
    field("body_mass")[rows, pole] = masses
    field("body_inertia")[rows, pole] = (0.4 * masses * TIP_RADIUS**2)[..., None]
    zeros = np.zeros_like(lengths)
    field("body_ipos")[rows, pole] = np.stack([zeros, zeros, lengths], axis=-1)
    field("geom_size")[rows, rod, 1] = half  # capsule half-length
    field("geom_pos")[rows, rod] = np.stack([zeros, zeros, half], axis=-1)
    field("geom_pos")[rows, tip] = np.stack([zeros, zeros, lengths], axis=-1)
    # Bounding volumes, so rendering does not cull a lengthened rod.
    field("geom_rbound")[rows, rod] = half + rod_radius
    aabb = np.stack([zeros, zeros, zeros, zeros + rod_radius, zeros + rod_radius, half + rod_radius], axis=-1)
    field("geom_aabb")[rows, rod] = aabb


class Physics(common.StatePhysics):
    """Pendulum physics with the paper's state ``[theta, theta_dot]``."""

    STATE_SIZE = 2

    def states_from(self, qpos: np.ndarray, qvel: np.ndarray) -> np.ndarray:
        qpos, qvel = np.asarray(qpos, np.float64), np.asarray(qvel, np.float64)
        return np.concatenate((wrap_angle(qpos[:, :1]), qvel[:, :1]), axis=1)

    def qpos_qvel_from(self, states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s = np.asarray(states, np.float64)
        return s[:, :1].copy(), s[:, 1:2].copy()

    def angle(self) -> float:
        """theta (rad) from upright, wrapped to [-pi, pi)."""
        return float(wrap_angle(self.data.qpos[0]))

    def angular_velocity(self) -> float:
        """theta_dot (rad/s)."""
        return float(self.data.qvel[0])

    def torque(self) -> float:
        """Torque the actuator applies at the hinge now (N m), after clipping and gear."""
        return float(self.data.qfrc_actuator[0])

    def pendulum_length(self) -> float:
        """Hinge to tip centre (m)."""
        return float(self.named.model.body_ipos["pole"][2])

    def pendulum_mass(self) -> float:
        """Tip mass (kg)."""
        return float(self.named.model.body_mass["pole"])

    def pendulum_ids(self) -> tuple[int, int, int]:
        """Ids of the pole body, the rod geom and the tip geom (looked up once: the time-varying
        task writes them every step, and named indexing costs several times the writes)."""
        ids = getattr(self, "_pendulum_ids", None)
        if ids is None:
            ids = self._pendulum_ids = (
                self.model.name2id("pole", "body"),
                self.model.name2id("rod", "geom"),
                self.model.name2id("tip", "geom"),
            )
        return ids

    def set_pendulum(self, length: float, mass: float) -> None:
        """Gives the pendulum a new length (m) and mass (kg) in the compiled model.

        Writes the mass properties and the geometry (as :func:`write_pendulum` does
        for many), then refreshes derived model fields with ``mj_setConst`` on a
        scratch MjData, so qpos, qvel and the rest of the live state are
        untouched; no recompiling. Ends with ``forward()``,
        so positions derived from the state (what a render shows) match the new
        geometry at once.
        """
        for name, value in (("length", length), ("mass", mass)):
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, float, np.floating, np.integer))
                or not math.isfinite(value)
                or value <= 0
            ):
                raise ValueError(f"set_pendulum {name} must be a finite number > 0, got {value!r}")
        length, mass = float(length), float(mass)
        # Scalar writes, not write_pendulum's arrays: the time-varying task's environment calls
        # this every step, at half the cost (tests/test_vector.py checks that both agree).
        pole, rod, tip = self.pendulum_ids()
        model = self.model.ptr
        model.body_mass[pole] = mass
        model.body_inertia[pole] = 0.4 * mass * TIP_RADIUS**2
        model.body_ipos[pole] = (0.0, 0.0, length)
        rod_radius = model.geom_size[rod, 0]
        model.geom_size[rod, 1] = length / 2.0  # capsule half-length
        model.geom_pos[rod] = (0.0, 0.0, length / 2.0)
        model.geom_pos[tip] = (0.0, 0.0, length)
        # Bounding volumes, so rendering does not cull a lengthened rod.
        model.geom_rbound[rod] = length / 2.0 + rod_radius
        model.geom_aabb[rod] = (0.0, 0.0, 0.0, rod_radius, rod_radius, length / 2.0 + rod_radius)
        scratch = getattr(self, "_scratch_data", None)
        if scratch is None:
            scratch = mujoco.MjData(self.model.ptr)
            self._scratch_data = scratch
        mujoco.mj_setConst(self.model.ptr, scratch)
        self.forward()


def make_physics(params: PendulumParams | None = None, flipped: bool = False, gain: float = 1.0) -> Physics:
    """A compiled pendulum with ``params`` applied; ``flipped`` reverses the control's sign,
    ``gain`` scales the torque a control gives (its actuator's gear)."""
    params = as_params(params)
    physics = common.compile_physics(Physics, *common.read_model("pendulum.xml"))
    model = physics.named.model
    model.actuator_gear["torque"][0] = -gain if flipped else gain
    model.actuator_ctrlrange["torque"] = (-params.max_torque, params.max_torque)
    physics.model.opt.gravity[:] = (0.0, 0.0, -params.gravity)
    physics.set_pendulum(params.length, params.mass)  # also runs mj_setConst
    return physics


class Task(common.StateTask):
    """Swing the pendulum up and hold it: reward ``-10 theta^2 - 5 theta_dot^2``."""

    def __init__(
        self,
        params: PendulumParams,
        timevarying: bool = False,
        random: Any = None,
        amplitude: float = SCHEDULE_AMPLITUDE,
        flipped: bool = False,
    ) -> None:
        super().__init__(random=random)
        self.params = params
        self.timevarying = timevarying
        self.amplitude = amplitude
        self.flipped = flipped  # the actuator's gear is -gain, not gain
        # The model changes every step, so mujoco.rollout cannot replay it.
        self.rollout_compatible = not timevarying
        self.step_index = 0

    def start_configurations(self, physics: Physics, n: int) -> tuple[np.ndarray, np.ndarray]:
        # Per episode theta then theta_dot, as n pairs of scalar draws; the hinge
        # angle is pi + u itself, not the wrapped paper angle.
        draws = self.random.uniform(-START_HALF_WIDTH, START_HALF_WIDTH, size=(n, 2))
        return np.pi + draws[:, :1], draws[:, 1:].copy()

    def initialize_episode(self, physics: Physics) -> None:
        self.step_index = 0
        if self.timevarying:
            physics.set_pendulum(*timevarying_schedule(0, self.params, self.amplitude))
        super().initialize_episode(physics)

    def before_step(self, action: Any, physics: Physics) -> None:
        self.model_for_step(physics, self.step_index)
        self.step_index += 1
        super().before_step(action, physics)

    def model_for_step(self, physics: Physics, step: int) -> None:
        """Gives ``physics`` the pendulum of control step ``step`` (the schedule's; a fixed one is left)."""
        if self.timevarying:
            physics.set_pendulum(*timevarying_schedule(step, self.params, self.amplitude))

    def batch_reward(self, states: np.ndarray) -> np.ndarray:
        s = np.asarray(states, np.float64)
        return -10.0 * s[:, 0] ** 2 - 5.0 * s[:, 1] ** 2

    def write_models(
        self,
        physics: Physics,
        field: Callable[[str], np.ndarray],
        ids: np.ndarray,
        values: Mapping[str, np.ndarray],
        steps: np.ndarray,
    ) -> None:
        """Writes into rows ``ids`` of a batch of ``physics``'s model (its per-simulation fields, ``field(name)``) the
        model each row's context ``values`` (arrays over ``ids``, every key of ``CONTEXTS``)
        gives at its episode's control step ``steps``: what :func:`make_physics` and
        :meth:`model_for_step` make, without building a physics per context. The caller
        then runs the batch's ``set_const`` for the derived fields."""
        lengths, masses = values["length"], values["mass"]
        if self.timevarying:
            # timevarying_schedule's numbers: math.cos per step, as the environment takes them.
            wave = values["amplitude"] * _schedule_cosines(int(steps.max()) + 1)[steps]
            lengths, masses = lengths + wave, masses + wave
        write_pendulum(field, physics.pendulum_ids(), ids, lengths, masses)
        field("opt.gravity")[ids, 2] = -values["gravity"]
        if "gain" in values:
            field("actuator_gear")[ids, 0, 0] = -values["gain"] if self.flipped else values["gain"]


def _schedule_cosines(n: int) -> np.ndarray:
    """``cos(pi i / 50)`` of control steps 0 .. n - 1 (at least), by ``math.cos`` as
    :func:`timevarying_schedule` computes them (numpy's cosine may differ in the last bit)."""
    return _cosines(max(256, 1 << (n - 1).bit_length()))


@functools.lru_cache(maxsize=None)
def _cosines(n: int) -> np.ndarray:
    return np.array([math.cos(math.pi * i / (SCHEDULE_PERIOD_STEPS / 2)) for i in range(n)])


def _environment(
    physics: Physics, task: Task, time_limit: float, environment_kwargs: dict[str, Any] | None
) -> common.Environment:
    return common.Environment(
        physics,
        task,
        time_limit=time_limit,
        control_timestep=CONTROL_TIMESTEP,
        **(environment_kwargs or {}),
    )


def swingup(
    time_limit: float = DEFAULT_TIME_LIMIT,
    random: Any = None,
    environment_kwargs: dict[str, Any] | None = None,
    params: PendulumParams | None = None,
) -> common.Environment:
    """The conventional pendulum swing-up (the paper's source IP)."""
    physics = make_physics(params)
    return _environment(physics, Task(as_params(params), random=random), time_limit, environment_kwargs)


def swingup_timevarying(
    time_limit: float = DEFAULT_TIME_LIMIT,
    random: Any = None,
    environment_kwargs: dict[str, Any] | None = None,
    params: PendulumParams | None = None,
    amplitude: float = SCHEDULE_AMPLITUDE,
) -> common.Environment:
    """Swing-up with length and mass following :func:`timevarying_schedule` every step;
    ``amplitude`` (m and kg, >= 0) is how far they swing about their nominal values."""
    params = as_params(params)
    amplitude = common.real(amplitude, "pendulum amplitude")
    if not (math.isfinite(amplitude) and amplitude >= 0):
        raise ValueError(f"amplitude must be a number >= 0 (m and kg), got {amplitude!r}")
    for name in ("length", "mass"):
        if getattr(params, name) <= amplitude:
            raise ValueError(
                f"PendulumParams.{name} must exceed the amplitude {amplitude} for swingup_timevarying "
                f"(the schedule subtracts up to it), got {getattr(params, name)!r}"
            )
    physics = make_physics(params)
    task = Task(params, timevarying=True, random=random, amplitude=amplitude)
    return _environment(physics, task, time_limit, environment_kwargs)


def swingup_flipped(
    time_limit: float = DEFAULT_TIME_LIMIT,
    random: Any = None,
    environment_kwargs: dict[str, Any] | None = None,
    params: PendulumParams | None = None,
    gain: float = 1.0,
) -> common.Environment:
    """Swing-up whose control acts with the opposite sign (the paper's negative transfer),
    scaled by ``gain`` (> 0: the torque per unit of control)."""
    gain = common.real(gain, "pendulum gain")
    if not (math.isfinite(gain) and gain > 0):
        raise ValueError(f"gain must be a number > 0, got {gain!r}")
    physics = make_physics(params, flipped=True, gain=gain)
    task = Task(as_params(params), random=random, flipped=True)
    return _environment(physics, task, time_limit, environment_kwargs)


def as_params(params: PendulumParams | None) -> PendulumParams:
    """``params``, or the defaults when None; anything else raises ValueError."""
    if params is None:
        return PendulumParams()
    if not isinstance(params, PendulumParams):
        raise ValueError(f"params must be a PendulumParams, got {type(params).__name__}")
    return params


def _amplitude_below_mass_and_length(values: Mapping[str, float]) -> None:
    for name in ("length", "mass"):
        if values[name] <= values["amplitude"]:
            raise ValueError(f"{name} {values[name]:g} must exceed the amplitude {values['amplitude']:g}")


_PHYSICAL = (
    ContextKey("mass", "kg", 0.1, 10.0, "model", "tip mass", in_params=True),
    ContextKey("length", "m", 0.1, 10.0, "model", "hinge to tip centre", in_params=True),
    ContextKey("gravity", "m/s^2", 0.1, 30.0, "model", "gravitational acceleration", in_params=True),
)
CONTEXTS = {
    "swingup": ContextSpec(_PHYSICAL, PendulumParams),
    "swingup_timevarying": ContextSpec(
        (*_PHYSICAL, ContextKey("amplitude", "m and kg", 0.0, 5.0, "task", "swing of length and mass")),
        PendulumParams,
        _amplitude_below_mass_and_length,
    ),
    "swingup_flipped": ContextSpec(
        (*_PHYSICAL, ContextKey("gain", "N m per unit of control", 0.05, 20.0, "model", "flipped torque gain")),
        PendulumParams,
    ),
}
"""Context keys by task (``tatl_mj.suite.contexts``); ``max_torque`` is not one: it sets the action space."""

TASKS = {
    "swingup": swingup,
    "swingup_timevarying": swingup_timevarying,
    "swingup_flipped": swingup_flipped,
}


def describe(task: str, params: PendulumParams | None = None, **_: Any) -> TaskDescription:
    """The pendulum's static facts (see ``tatl_mj.description``).

    Mappings measure the angle from hanging (``angle_origin`` pi): random-policy
    data stay near hanging, which is exactly where theta wraps.
    """
    limit = as_params(params).max_torque
    return TaskDescription(
        domain="pendulum",
        task=task,
        dynamics_version=DYNAMICS_VERSION,
        state_names=("theta", "theta_dot"),
        periodic=(True, False),
        angle_origin=(math.pi, 0.0),
        action_values=ACTIONS,
        discrete=False,
        control_timestep=CONTROL_TIMESTEP,
        action_low=np.array([-limit]),
        action_high=np.array([limit]),
        # Every angle, and the speeds the source's FQI box covers.
        reset_low=np.array([-math.pi, -8.0]),
        reset_high=np.array([math.pi, 8.0]),
        gymnasium_peer="Pendulum-v1" if task == next(iter(TASKS)) else None,
    )
