"""Mountain car climb: an under-powered car must rock back and forth to leave a valley.

The classic problem (Moore 1990; Sutton & Barto) as a real MuJoCo simulation: a
car is held by a linkage on the classic hill ``h(x) = 0.45 sin(3x) + 0.55``
(drawn as a heightfield), moves without friction, and is pushed by a horizontal force too weak to
climb the right slope directly. The paper's source task for the pendulum swing-up.

=================  ==========================================================
State              ``[x, v]`` (float64)
                   x: horizontal position of the wheel centre (m), classic
                   range [-1.2, 0.6]; a wall stops the car at -1.2;
                   ``set_state_vector`` accepts x in [-1.25, 0.8];
                   v: horizontal velocity in the classic per-step unit,
                   ``v = x_dot * VELOCITY_SCALE`` with x_dot in m/s and
                   ``VELOCITY_SCALE = CONTROL_TIMESTEP = 0.014`` s, i.e. metres
                   moved per control step. The classic range is
                   [-0.07, 0.07]; here nothing is clipped, energy alone
                   bounds v: pumping from the start set peaks near 0.063, and
                   the fastest possible (pushed left from rest at the goal
                   line) is about 0.074 under the default parameters.
Actions            ``ACTIONS = [[-1], [0], [1]]``: throttle full left / none /
                   full right (the paper's -1, 0, +1). The actuator's gear is
                   the full horizontal force, ``force`` (default 5.3 N), so the
                   action set does not change when the force does.
Reward             ``-(x - 0.5)^2`` after every step (minus the squared
                   distance to the goal, as in the paper).
Start state        x uniform in [-0.6, -0.4] from the task's ``random``, at rest
                   on the slope.
Episode end        goal, with discount 0: ``x >= 0.5``; otherwise the time
                   limit (default 5.6 s = 400 control steps, twice the classic
                   200, because the real dynamics climb a little more slowly),
                   which is not a failure.
Timing             control step 0.014 s; one RK4 physics step of 0.014 s
                   per action (nothing stiff is simulated).
Parameters         :class:`MountainCarParams`: car_mass 1 kg, force 5.3 N,
                   gravity 9.81 m/s^2, damping 0 N s/m (viscous, on x).
=================  ==========================================================

Physics. A crank and a rocker, tied to x by hard joint equalities, hold the
wheel centre (3 cm wheel) exactly on ``z = h(x) + r`` and keep the car level,
and the mass is split between the car, a vertically moving slider and the two
spinning links so that the whole acts as one point mass m on the curve
(assets/mjcf/mountain_car.xml, ``BALLAST``). So the motion is that of a bead on the
classic curve::

    m (1 + h'^2) x_dd + m h' h'' x_d^2 = F - m g h'(x) - c x_d

and ``E = m (1 + h'^2) x_d^2 / 2 + m g h(x)`` changes only by the work of F and
c. The classic update ``v += 0.001 a - 0.0025 cos(3x)`` is this equation without
the ``1 + h'^2`` and ``h' h''`` terms, written per step: its gravity
``0.0025 / 1.35`` per step^2 equals ``g dt^2`` for ``dt = 0.0137`` s, which is
why the control step is 0.014 s (the valley's small-oscillation period is then
72 steps, as in the classic task) and why the default force 5.3 N is the
classic ratio ``force / (m g) = 0.001 / (0.0025 / 1.35) = 0.54``. Pushing at
full throttle from the valley stalls on the right slope (it would need
``force / (m g)`` above 0.8); pushing along the velocity reaches the goal.

Measured (tests/test_mountain_car.py): full throttle from the start set
peaks at x = -0.15; pushing along the velocity reaches the goal in 150 to 170
steps. Over 100 steps the simulated x stays within 4 um of the bead equation
above solved by scipy (the heightfield version: 0.8 mm); the wheel centre stays
within 0.01 mm of ``h(x) + r`` and the energy of free rolling within 1e-4 of
the swing over 10 s.

The wall is a hard, over-damped lower limit on x at -1.2, which stops motion
along the track as the classic task's wall does; evaluated once per 14 ms step,
it gives up to about 3 cm when the car hits it fast (pushed left at full speed).
"""

from __future__ import annotations

import dataclasses
import xml.etree.ElementTree as ET
from typing import Any

import mujoco
import numpy as np

from tatl_mj.description import TaskDescription
from tatl_mj.suite import common
from tatl_mj.suite.contexts import ContextKey, ContextSpec

CONTROL_TIMESTEP = 0.014  # s; one RK4 physics step
VELOCITY_SCALE = CONTROL_TIMESTEP  # v (m per control step) = x_dot (m/s) * this
DEFAULT_TIME_LIMIT = 400 * CONTROL_TIMESTEP  # s, 400 control steps
GOAL_X = 0.5  # m
X_MIN, X_MAX = -1.2, 0.6  # m, classic position range (the wall is at X_MIN)
# The camera clips film from (tatl_mj.render): fixed, side-on, the whole hill in view.
CAMERA = "tracking"
V_MAX = 0.07  # classic velocity bound (m per control step), not enforced
START_RANGE = (-0.6, -0.4)  # m
# Positions a state may be set to: the classic range plus room for the wall's
# give (the car presses up to about 3 cm into it) and past the goal; the drawn
# heightfield runs over [-1.35, 0.85].
SETTABLE_X = (-1.25, 0.8)  # m

ACTIONS = np.array([[-1.0], [0.0], [1.0]])
DYNAMICS_VERSION = 1  # of every task here; docs/versions.md says when it is bumped

_HILL_AMPLITUDE, _HILL_FREQUENCY, _HILL_OFFSET = 0.45, 3.0, 0.55


def hill_height(x: np.ndarray | float) -> np.ndarray:
    """The classic hill ``0.45 sin(3x) + 0.55`` (m) at horizontal position x (m)."""
    return _HILL_AMPLITUDE * np.sin(_HILL_FREQUENCY * np.asarray(x)) + _HILL_OFFSET


def hill_slope(x: np.ndarray | float) -> np.ndarray:
    """dh/dx of :func:`hill_height` (dimensionless)."""
    return _HILL_AMPLITUDE * _HILL_FREQUENCY * np.cos(_HILL_FREQUENCY * np.asarray(x))


def hill_curvature(x: np.ndarray | float) -> np.ndarray:
    """d2h/dx2 of :func:`hill_height` (1/m)."""
    return -_HILL_AMPLITUDE * _HILL_FREQUENCY**2 * np.sin(_HILL_FREQUENCY * np.asarray(x))


@dataclasses.dataclass(frozen=True)
class MountainCarParams:
    """Physical parameters of the mountain car; non-physical values raise ValueError."""

    car_mass: float = common.positive(1.0, "car mass (kg)")
    force: float = common.positive(5.3, "full-throttle horizontal force (N)")
    gravity: float = common.positive(9.81, "gravitational acceleration (m/s^2)")
    damping: float = common.nonnegative(0.0, "viscous damping on x (N s/m)")

    def __post_init__(self) -> None:
        common.check_params(self)


def model_xml(params: MountainCarParams | None = None) -> tuple[str, dict[str, bytes]]:
    """The MJCF text (with ``params`` and the hill's shape written in) and its include files."""
    params = MountainCarParams() if params is None else params
    root, assets = common.parse_model("mountain_car.xml", params, MountainCarParams)
    _pose_wall(root)
    _shape_linkage(root, params.car_mass)
    root.find("option").set("gravity", f"0 0 {-params.gravity!r}")
    root.find(".//joint[@name='x']").set("damping", repr(params.damping))
    root.find(".//motor[@name='throttle']").set("gear", repr(params.force))
    return ET.tostring(root, encoding="unicode"), assets


def _wheel_radius(root: ET.Element) -> float:
    return float(root.find(".//geom[@name='wheel']").get("size").split()[0])


def _pose_wall(root: ET.Element) -> None:
    """Turns the (drawn) wall's face square to the track at x = -1.2, r from the wheel centre.

    Written into the XML because MuJoCo fixes the pose of world-body geoms when
    it compiles. The wall's physics is the lower limit of joint x.
    """
    radius = _wheel_radius(root)
    wall = root.find(".//geom[@name='wall']")
    half_thickness = float(wall.get("size").split()[0])
    # A rotation about y by -atan(h') takes the wall's local x to the tangent t.
    angle = -float(np.arctan(hill_slope(X_MIN)))
    tangent = np.array([np.cos(angle), 0.0, -np.sin(angle)])
    centre = np.array([X_MIN, 0.0, float(hill_height(X_MIN)) + radius])
    pos = centre - (radius + half_thickness) * tangent
    wall.set("pos", " ".join(repr(float(v)) for v in pos))
    wall.set("quat", f"{float(np.cos(angle / 2))!r} 0 {float(np.sin(angle / 2))!r} 0")
    root.find(".//joint[@name='x']").set("range", f"{X_MIN!r} 10")


# Share of the car's mass carried by the slider, which the linkage moves only
# vertically; the crank and the rocker each get a moment of inertia of
# BALLAST * m / 18 and the linkage spins both at 3 x_dot, so the extra
# horizontal inertia 9 * 2 * BALLAST * m / 18 equals the slider's extra vertical
# mass and the whole acts as one point mass m on the curve. Real inertia on
# every hinge keeps the hard equalities hard: MuJoCo scales a constraint's
# softness by the inverse inertia it acts on, so near-massless links let it give.
BALLAST = 0.9
X_INDEX = 3  # qpos / qvel index of the slide x: crank, rocker, level, x down the chain


def _shape_linkage(root: ET.Element, car_mass: float) -> None:
    """Writes the hill and the masses into the linkage (see assets/mjcf/mountain_car.xml):
    crank pivot at 0.55 + r, links A/2, crank at 3x, and the mass split by BALLAST.
    """
    root.find(".//body[@name='crank']").set("pos", f"0 0 {_HILL_OFFSET + _wheel_radius(root)!r}")
    for body in ("rocker", "slider"):
        root.find(f".//body[@name='{body}']").set("pos", f"{_HILL_AMPLITUDE / 2!r} 0 0")
    polycoef = {
        "crank_follows_x": (0.0, _HILL_FREQUENCY),  # theta = 3x
        "rocker_mirrors_crank": (np.pi, -2.0),  # rocker's world angle theta + psi = pi - theta
        "slider_stays_level": (-np.pi, 1.0),  # slider's world angle (pi - theta) + chi = 0
    }
    for name, (c0, c1) in polycoef.items():
        root.find(f".//equality/joint[@name='{name}']").set("polycoef", f"{c0!r} {c1!r} 0 0 0")
    ballast = BALLAST * car_mass
    spin = ballast / (2 * _HILL_FREQUENCY**2)  # crank and rocker each
    for body in ("crank", "rocker"):
        root.find(f".//body[@name='{body}']/inertial").set("diaginertia", f"{spin!r} {spin!r} {spin!r}")
    root.find(".//body[@name='crank']/inertial").set("mass", repr(ballast))  # on its fixed pivot
    root.find(".//body[@name='slider']/inertial").set("mass", repr(ballast))
    root.find(".//geom[@name='wheel']").set("mass", repr(car_mass - ballast))


def linkage_angles(x: np.ndarray, x_dot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hinge angles (crank, rocker, level) and their rates that put the car at x, (N, 3) each."""
    k = _HILL_FREQUENCY
    angles = np.stack([k * x, np.pi - 2 * k * x, k * x - np.pi], axis=1)
    rates = np.stack([k * x_dot, -2 * k * x_dot, k * x_dot], axis=1)
    return angles, rates


class Physics(common.StatePhysics):
    """Mountain-car physics; the state is ``[x, v]`` (m, m per control step)."""

    STATE_SIZE = 2

    def wheel_radius(self) -> float:
        """Radius of the wheel sphere (m)."""
        return float(self.named.model.geom_size["wheel", 0])

    def position(self) -> float:
        """Horizontal position of the carriage, x (m): the wheel centre's while the linkage holds."""
        return float(self.named.data.qpos["x"][0])

    def velocity(self) -> float:
        """Horizontal velocity x_dot (m/s)."""
        return float(self.named.data.qvel["x"][0])

    def car_mass(self) -> float:
        """The mass m the car acts with on the curve (kg): the car body's plus the slider's."""
        return float(self.named.model.body_mass["car"] + self.named.model.body_mass["slider"])

    def _evaluated(self) -> Any:
        """A scratch MjData at the current state with positions and inertia computed.

        Not self.data: forward() there would change what the next step starts from.
        """
        scratch = getattr(self, "_scratch", None)
        if scratch is None:
            scratch = self._scratch = mujoco.MjData(self.model.ptr)
        scratch.qpos[:] = self.data.qpos
        scratch.qvel[:] = self.data.qvel
        mujoco.mj_kinematics(self.model.ptr, scratch)
        mujoco.mj_comPos(self.model.ptr, scratch)
        mujoco.mj_crb(self.model.ptr, scratch)
        return scratch

    def height(self) -> float:
        """Height of the wheel centre above the hill's zero (m); h(x) + r on the track.

        Forward kinematics of the linkage from the joint state, so a linkage that
        gives shows up here.
        """
        return float(self._evaluated().xpos[self.model.name2id("car", "body")][2])

    def mechanical_energy(self) -> float:
        """Kinetic plus gravitational energy of the whole mechanism (J), zero height at z = 0."""
        scratch = self._evaluated()
        mass_matrix = np.zeros((self.model.nv, self.model.nv))
        mujoco.mj_fullM(self.model.ptr, scratch, mass_matrix)
        kinetic = 0.5 * float(scratch.qvel @ mass_matrix @ scratch.qvel)
        potential = -float(np.sum(self.model.body_mass * (scratch.xipos @ self.model.opt.gravity)))
        return kinetic + potential

    def states_from(self, qpos: np.ndarray, qvel: np.ndarray) -> np.ndarray:
        # concatenate, not stack: half the cost for one row (dm_control's loop)
        return np.concatenate((qpos[:, X_INDEX, None], qvel[:, X_INDEX, None] * VELOCITY_SCALE), axis=1)

    def qpos_qvel_from(self, states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        # On the track, moving along it: the hinges at the angles the equalities ask.
        x = states[:, 0]
        outside = (x < SETTABLE_X[0]) | (x > SETTABLE_X[1])
        if np.any(outside):
            raise ValueError(
                f"mountain_car state x must be in [{SETTABLE_X[0]}, {SETTABLE_X[1]}] m "
                f"(the track), got {x[outside][0]!r}"
            )
        x_dot = states[:, 1] / VELOCITY_SCALE
        angles, rates = linkage_angles(x, x_dot)
        return np.column_stack([angles, x]), np.column_stack([rates, x_dot])


def _build_hill(physics: Physics) -> None:
    """Fills in the drawn hill: heights one wheel radius below the wheel centre's
    path ``c(s) = (s, h(s) + r)`` along its upward unit normal n(s), so the wheel
    is drawn touching it.

    The offset stays a graph over x because r is well under the hill's smallest
    radius of curvature (0.25 m); sampled densely in s and interpolated onto
    the heightfield's columns.
    """
    radius = physics.wheel_radius()
    half_length = float(physics.named.model.hfield_size["hill", 0])
    scale = float(physics.named.model.hfield_size["hill", 2])
    nrow, ncol = int(physics.named.model.hfield_nrow["hill"]), int(physics.named.model.hfield_ncol["hill"])
    centre_x = float(physics.named.model.geom_pos["hill", 0])
    s = np.linspace(centre_x - half_length - 2 * radius, centre_x + half_length + 2 * radius, 20 * ncol)
    slope = hill_slope(s)
    norm = np.sqrt(1.0 + slope**2)
    columns = np.linspace(centre_x - half_length, centre_x + half_length, ncol)
    surface = np.interp(columns, s + radius * slope / norm, hill_height(s) + radius - radius / norm)
    start = int(physics.named.model.hfield_adr["hill"])
    physics.model.hfield_data[start : start + nrow * ncol] = np.tile(surface / scale, nrow)


def make_physics(params: MountainCarParams | None = None) -> Physics:
    """Compiles the model with ``params`` and fills in the drawn hill."""
    physics = common.compile_physics(Physics, *model_xml(params))
    _build_hill(physics)
    return physics


class Climb(common.StateTask):
    """Reach x >= 0.5 (absorbing); reward ``-(x - 0.5)^2`` every step."""

    def start_configurations(self, physics: Physics, n: int) -> tuple[np.ndarray, np.ndarray]:
        x = self.random.uniform(*START_RANGE, size=n)
        return physics.qpos_qvel_from(np.column_stack([x, np.zeros(n)]))

    def batch_reward(self, states: np.ndarray) -> np.ndarray:
        return -((states[:, 0] - GOAL_X) ** 2)

    def batch_absorbing(self, states: np.ndarray) -> np.ndarray:
        return states[:, 0] >= GOAL_X


def climb(
    time_limit: float = DEFAULT_TIME_LIMIT,
    random: Any = None,
    environment_kwargs: dict[str, Any] | None = None,
    params: MountainCarParams | None = None,
) -> common.Environment:
    """Returns the mountain-car climb task (see the module docstring)."""
    physics = make_physics(params)
    task = Climb(random=random)
    return common.Environment(
        physics,
        task,
        time_limit=time_limit,
        control_timestep=CONTROL_TIMESTEP,
        **(environment_kwargs or {}),
    )


TASKS = {"climb": climb}

CONTEXTS = {
    "climb": ContextSpec(
        (
            ContextKey("car_mass", "kg", 0.1, 10.0, "model", "car mass", True),
            ContextKey("force", "N", 0.5, 50.0, "model", "full-throttle horizontal force", True),
            ContextKey("gravity", "m/s^2", 0.1, 30.0, "model", "gravitational acceleration", True),
            ContextKey("damping", "N s/m", 0.0, 10.0, "model", "viscous damping on x", True),
        ),
        MountainCarParams,
    )
}
"""Context keys (``tatl_mj.suite.contexts``)."""


def describe(task: str, **_: Any) -> TaskDescription:
    """The mountain car's static facts (see ``tatl_mj.description``)."""
    return TaskDescription(
        domain="mountain_car",
        task=task,
        dynamics_version=DYNAMICS_VERSION,
        state_names=("x", "v"),
        periodic=(False, False),
        action_values=ACTIONS,
        discrete=False,
        control_timestep=CONTROL_TIMESTEP,
        action_low=np.array([-1.0]),
        action_high=np.array([1.0]),
        gymnasium_peer="MountainCar-v0" if task == next(iter(TASKS)) else None,
        state_low=np.array([SETTABLE_X[0], -np.inf]),
        state_high=np.array([SETTABLE_X[1], np.inf]),
        # The classic task's box: the valley from the left wall to the goal, its speed limits.
        reset_low=np.array([-1.2, -0.07]),
        reset_high=np.array([0.6, 0.07]),
    )
