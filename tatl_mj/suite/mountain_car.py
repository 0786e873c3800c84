"""Mountain car climb: an under-powered car must rock back and forth to leave a valley.

The classic problem (Moore 1990; Sutton & Barto) as a real MuJoCo simulation: a
car slides without friction on a heightfield shaped like the classic hill
``h(x) = 0.45 sin(3x) + 0.55`` and is pushed by a horizontal force too weak to
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
Timing             control step 0.014 s; physics step 0.002 s (RK4), so seven
                   physics steps per action.
Parameters         :class:`MountainCarParams`: car_mass 1 kg, force 5.3 N,
                   gravity 9.81 m/s^2, damping 0 N s/m (viscous, on x).
=================  ==========================================================

Physics. The wheel (a 3 cm sphere) is the only colliding part; its centre moves
on ``z = h(x) + r``, so with no damping the motion is that of a bead on the
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
steps. Over 100 steps the simulated x stays within 1 mm of the bead equation
above solved by scipy.

Contact choices (see ``assets/mjcf/mountain_car.xml``): the hill is a 1 mm
heightfield on which the wheel centre rides exactly on ``h(x) + r``; an
upside-down, hidden heightfield 0.5 mm above the wheel keeps the car on the
track where it would fly off the crest near the goal; both contacts are
frictionless and undamped (a stiff spring, 3e5 m/s^2 per m), because any
damping turns the facets' small normal velocities into a steady energy loss.
The wall's face is square to the track and its contact stiff and over-damped,
so the car stops there as in the classic task. With no force and no damping
the energy drifts by under 0.5% in 10 s, and the wheel centre stays within
1 mm of ``h(x) + r``.
"""

from __future__ import annotations

import dataclasses
import xml.etree.ElementTree as ET
from typing import Any

import numpy as np

from tatl_mj.description import TaskDescription
from tatl_mj.suite import common

CONTROL_TIMESTEP = 0.014  # s; 7 physics steps of 2 ms
VELOCITY_SCALE = CONTROL_TIMESTEP  # v (m per control step) = x_dot (m/s) * this
DEFAULT_TIME_LIMIT = 400 * CONTROL_TIMESTEP  # s, 400 control steps
GOAL_X = 0.5  # m
X_MIN, X_MAX = -1.2, 0.6  # m, classic position range (the wall is at X_MIN)
V_MAX = 0.07  # classic velocity bound (m per control step), not enforced
START_RANGE = (-0.6, -0.4)  # m
# Positions a state may be set to: the classic range plus room for the wall's
# give (the car presses up to 8 mm into it) and past the goal; the track's
# heightfields run over [-1.35, 0.85].
SETTABLE_X = (-1.25, 0.8)  # m

ACTIONS = np.array([[-1.0], [0.0], [1.0]])

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
    """The MJCF text (with ``params`` written in) and its include files."""
    params = MountainCarParams() if params is None else params
    root, assets = common.parse_model("mountain_car.xml", params, MountainCarParams)
    _pose_wall(root)
    root.find("option").set("gravity", f"0 0 {-params.gravity!r}")
    root.find(".//geom[@name='wheel']").set("mass", repr(params.car_mass))
    root.find(".//joint[@name='x']").set("damping", repr(params.damping))
    root.find(".//motor[@name='throttle']").set("gear", repr(params.force))
    return ET.tostring(root, encoding="unicode"), assets


def _pose_wall(root: ET.Element) -> None:
    """Turns the wall's face square to the track at x = -1.2, r from the wheel centre.

    So the wall stops the motion along the track (as the classic task zeroes
    the velocity) without launching the car off the slope. Written into the
    XML because MuJoCo fixes the pose of world-body geoms when it compiles.
    """
    radius = float(root.find(".//geom[@name='wheel']").get("size").split()[0])
    wall = root.find(".//geom[@name='wall']")
    half_thickness = float(wall.get("size").split()[0])
    # A rotation about y by -atan(h') takes the wall's local x to the tangent t.
    angle = -float(np.arctan(hill_slope(X_MIN)))
    tangent = np.array([np.cos(angle), 0.0, -np.sin(angle)])
    centre = np.array([X_MIN, 0.0, float(hill_height(X_MIN)) + radius])
    pos = centre - (radius + half_thickness) * tangent
    wall.set("pos", " ".join(repr(float(v)) for v in pos))
    wall.set("quat", f"{float(np.cos(angle / 2))!r} 0 {float(np.sin(angle / 2))!r} 0")


class Physics(common.StatePhysics):
    """Mountain-car physics; the state is ``[x, v]`` (m, m per control step)."""

    STATE_SIZE = 2

    def wheel_radius(self) -> float:
        """Radius of the colliding wheel sphere (m)."""
        return float(self.named.model.geom_size["wheel", 0])

    def position(self) -> float:
        """Horizontal position of the wheel centre, x (m)."""
        return float(self.named.data.qpos["x"][0])

    def velocity(self) -> float:
        """Horizontal velocity x_dot (m/s)."""
        return float(self.named.data.qvel["x"][0])

    def height(self) -> float:
        """Height of the wheel centre above the hill's zero (m); h(x) + r on the surface."""
        return float(self.named.data.qpos["z"][0])

    def mechanical_energy(self) -> float:
        """Kinetic plus gravitational energy of the car (J), zero height at z = 0."""
        mass = float(self.named.model.body_mass["car"])
        speed2 = float(np.sum(self.data.qvel**2))
        return 0.5 * mass * speed2 + mass * -float(self.model.opt.gravity[2]) * self.height()

    def states_from(self, qpos: np.ndarray, qvel: np.ndarray) -> np.ndarray:
        return np.stack([qpos[:, 0], qvel[:, 0] * VELOCITY_SCALE], axis=1)

    def qpos_qvel_from(self, states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        # On the surface, moving along it: z = h(x) + r and z_dot = h'(x) x_dot.
        x = states[:, 0]
        outside = (x < SETTABLE_X[0]) | (x > SETTABLE_X[1])
        if np.any(outside):
            raise ValueError(
                f"mountain_car state x must be in [{SETTABLE_X[0]}, {SETTABLE_X[1]}] m "
                f"(the track), got {x[outside][0]!r}"
            )
        x_dot = states[:, 1] / VELOCITY_SCALE
        qpos = np.stack([x, hill_height(x) + self.wheel_radius()], axis=1)
        qvel = np.stack([x_dot, hill_slope(x) * x_dot], axis=1)
        return qpos, qvel


GUIDE_CLEARANCE = 0.0005  # m, free play between the wheel and the upper guide


def _offset_profile(physics: Physics, geom: str, distance: float) -> np.ndarray:
    """Heights (m) under the columns of hfield ``geom`` of the curve offset from the
    wheel-centre line ``c(s) = (s, h(s) + r)`` by ``distance`` along its upward
    unit normal n(s).

    A wheel of radius r whose centre rides on c touches c - r n from above; the
    offset stays a graph over x because |distance| is well under the hill's
    smallest radius of curvature (0.25 m). Sampled densely in s and
    interpolated onto the columns.
    """
    half_length = float(physics.named.model.hfield_size[geom, 0])
    ncol = int(physics.named.model.hfield_ncol[geom])
    centre_x = float(physics.named.model.geom_pos[geom, 0])
    margin = 2 * abs(distance)
    s = np.linspace(centre_x - half_length - margin, centre_x + half_length + margin, 20 * ncol)
    slope = hill_slope(s)
    norm = np.sqrt(1.0 + slope**2)
    offset_x = s - distance * slope / norm
    offset_z = hill_height(s) + physics.wheel_radius() + distance / norm
    columns = np.linspace(centre_x - half_length, centre_x + half_length, ncol)
    return np.interp(columns, offset_x, offset_z)


def _set_elevation(physics: Physics, hfield: str, elevation: np.ndarray) -> None:
    nrow = int(physics.named.model.hfield_nrow[hfield])
    start = int(physics.named.model.hfield_adr[hfield])
    physics.model.hfield_data[start:start + nrow * elevation.size] = np.tile(elevation, nrow)


def _build_track(physics: Physics) -> None:
    """Fills in the hill and the guide from :func:`hill_height`.

    - hill (upright hfield): surface ``c - r n``, so the resting wheel centre is
      exactly on ``h(x) + r``;
    - guide (upside-down hfield, geom z at its top): lower face ``c + (r + 0.5 mm) n``,
      which keeps the wheel on the track where the car would otherwise leave
      it, i.e. fly off the convex crest near the goal (above about 1.6 m/s).
    """
    radius = physics.wheel_radius()
    hill_scale = float(physics.named.model.hfield_size["hill", 2])
    _set_elevation(physics, "hill", _offset_profile(physics, "hill", -radius) / hill_scale)

    guide_top = float(physics.named.model.geom_pos["guide", 2])
    guide_scale = float(physics.named.model.hfield_size["guide", 2])
    guide = _offset_profile(physics, "guide", radius + GUIDE_CLEARANCE)
    _set_elevation(physics, "guide", (guide_top - guide) / guide_scale)


def make_physics(params: MountainCarParams | None = None) -> Physics:
    """Compiles the model with ``params`` and fills in the hill."""
    physics = Physics.from_xml_string(*model_xml(params))
    _build_track(physics)
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
        physics, task, time_limit=time_limit, control_timestep=CONTROL_TIMESTEP,
        **(environment_kwargs or {}),
    )


TASKS = {"climb": climb}


def describe(task: str, **_: Any) -> TaskDescription:
    """The mountain car's static facts (see ``tatl_mj.description``)."""
    return TaskDescription(
        domain="mountain_car", task=task, state_names=("x", "v"), periodic=(False, False),
        action_values=ACTIONS, discrete=False, control_timestep=CONTROL_TIMESTEP,
        action_low=np.array([-1.0]), action_high=np.array([1.0]),
        state_low=np.array([SETTABLE_X[0], -np.inf]), state_high=np.array([SETTABLE_X[1], np.inf]),
    )
