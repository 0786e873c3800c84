"""Bicycle balance: the Whipple benchmark bicycle below its self-stable speed.

The bicycle of Meijaard, Papadopoulos, Ruina & Schwab (2007, Proc. R. Soc. A 463,
"Linearized dynamics equations for the balance and steer of a bicycle: a benchmark
and review"), built from rigid bodies whose two knife-edge tyres roll on the floor
through MuJoCo contacts. A rear-wheel speed servo holds the forward speed, the
rider's centre of gravity is displaced sideways at random (Randlov & Alstrom 1998)
and the agent applies a torque to the handlebar. The paper's target task for transfer from the cart-pole.

=================  ==========================================================
State              ``[theta, theta_dot, omega, omega_dot]`` (float64)
                   theta: steer (handlebar) angle (rad), the front frame's
                   rotation about the steer axis, positive to the right;
                   theta_dot: steer rate (rad/s);
                   omega: roll angle of the rear frame from vertical (rad),
                   positive when leaning right;
                   omega_dot: roll rate (rad/s).
                   Signs are the benchmark's; the MuJoCo frame is x forward,
                   y left, z up.
Actions            ``ACTIONS = [[-2], [0], [2]]``: handlebar torque (N m),
                   positive turns the handlebar to the right. The actuator
                   accepts any torque in +-2 N m (action spec shape (1,)).
Control vector     ``ctrl = [steer torque (N m), rider CG offset d (m, +y =
                   left), the same d, forward speed set-point (m/s)]``; the
                   task fills in the last three (``Task.controls``).
Rider noise        every control step the 60 kg rider's centre of gravity
                   is displaced sideways by d, drawn anew uniform in
                   +-``cg_noise`` (default 0.02 m) from the task's
                   ``random`` (nothing is drawn when ``cg_noise = 0``), as
                   Randlov & Alstrom 1998 do. It acts as the displaced
                   weight's extra moment d y x (-m g z) (a couple, exact in
                   any pose); nothing moves, so no reaction shakes the
                   frame. RMS kick per step at 2 cm: roll rate 1.1e-3
                   rad/s, steer rate 8e-3 rad/s (docs/bicycle.md).
Reward             +1 for every step that ends upright, 0 on the step that
                   ends in a fall (as the cart-pole source task), so the
                   return counts control steps balanced (x 0.01 s = the
                   paper's "time balanced").
Start state        upright, steer 0, roll uniform in +-1 deg, rates 0,
                   rolling straight ahead at ``speed`` without slip.
Episode end        a fall, with discount 0: ``|omega| > pi/15`` (12 deg,
                   Randlov & Alstrom 1998); otherwise the time limit
                   (default 1000 s, the paper's), which is not a failure.
Timing             control step 0.01 s; physics step 0.001 s (implicitfast),
                   so 10 physics steps per action.
Parameters         ``speed`` (m/s, default 2.778 = 10 km/h, below the
                   benchmark's self-stable window 4.29..6.02 m/s),
                   ``cg_noise`` (m, default 0.02), ``start_roll`` (rad,
                   default 1 degree: the start roll's range, below the
                   12 degree fall), :class:`BicycleParams`:
                   tyre_half_width 0.005 m, rider_mass 60 kg (of the rear
                   body's 85; the mass whose weight d displaces),
                   tyre_friction 1.2, gravity 9.81 m/s^2.
=================  ==========================================================

Geometry and masses are the benchmark's Table 1 (see ``assets/mjcf/bicycle.xml``);
docs/bicycle.md compares the measured stability window with the benchmark's.
"""

from __future__ import annotations

import dataclasses
import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from typing import Any, Sequence

import numpy as np
from dm_env import specs

from tatl_mj.description import TaskDescription
from tatl_mj.suite import common
from tatl_mj.suite.contexts import ContextKey, ContextSpec

# Benchmark geometry (Meijaard et al. 2007, Table 1).
WHEELBASE = 1.02  # m
TRAIL = 0.08  # m
STEER_TILT = math.pi / 10  # rad, steer axis back from vertical
REAR_RADIUS = 0.3  # m
FRONT_RADIUS = 0.35  # m
REAR_BODY_MASS = 85.0  # kg, frame and rider together

CONTROL_TIMESTEP = 0.01  # s
DEFAULT_TIME_LIMIT = 1000.0  # s, the paper's
DEFAULT_SPEED = 2.778  # m/s, 10 km/h
DEFAULT_CG_NOISE = 0.02  # m
ROLL_LIMIT = math.pi / 15  # rad, 12 degrees
_PITCH_TOLERANCE = 1e-14  # rad, last Newton step of frame_pitch
_PITCH_DELTA = 1e-6  # rad, central difference for its slope
_PITCH_MAX_ITERATIONS = 50
START_ROLL = math.radians(1.0)  # rad, start roll uniform in +-START_ROLL
MAX_CG_NOISE = 0.25  # m, the CG actuators' control range
CG_ARM = 0.5  # m, half the distance between the two forces of the rider's couple
TORQUE_LIMIT = 2.0  # N m

ACTIONS = np.array([[-TORQUE_LIMIT], [0.0], [TORQUE_LIMIT]])
DYNAMICS_VERSION = 1  # of every task here; docs/versions.md says when it is bumped
# The camera clips film from (tatl_mj.render): from behind, so the roll (what the task is
# about) is across the line of sight; the side-on "tracking" camera looks along it.
CAMERA = "behind"

# Points of the front assembly in the rear frame's body coordinates (origin at the
# rear wheel centre, axes of the upright bicycle): steer-axis point level with the
# front wheel centre, the axis direction (pointing down), the front wheel centre.
_STEER_POINT = np.array([WHEELBASE + TRAIL - FRONT_RADIUS * math.tan(STEER_TILT), 0.0, FRONT_RADIUS - REAR_RADIUS])
_STEER_AXIS = np.array([math.sin(STEER_TILT), 0.0, -math.cos(STEER_TILT)])
_FRONT_CENTRE = np.array([WHEELBASE, 0.0, FRONT_RADIUS - REAR_RADIUS])
_Y = np.array([0.0, 1.0, 0.0])
_Z = np.array([0.0, 0.0, 1.0])


@dataclasses.dataclass(frozen=True)
class BicycleParams:
    """Physical parameters beyond the benchmark's; non-physical values raise ValueError."""

    tyre_half_width: float = common.positive(
        0.005, "half-width of the ellipsoid tyres (m); crown radius is width^2 / radius"
    )
    rider_mass: float = common.positive(
        60.0, "rider's share of the 85 kg rear body (kg), the mass the CG noise displaces"
    )
    tyre_friction: float = common.positive(1.2, "tyre-floor sliding friction coefficient")
    gravity: float = common.positive(9.81, "gravitational acceleration (m/s^2)")

    def __post_init__(self) -> None:
        common.check_params(self)
        if self.rider_mass >= REAR_BODY_MASS:
            raise ValueError(
                f"BicycleParams.rider_mass must be < {REAR_BODY_MASS} kg (the rear body), got {self.rider_mass!r}"
            )


def model_xml(params: BicycleParams | None = None) -> tuple[str, dict[str, bytes]]:
    """The MJCF text (with ``params`` written in) and its include files."""
    if params is None:
        return common.read_model("bicycle.xml")
    root, assets = common.parse_model("bicycle.xml", params, BicycleParams)
    root.find("option").set("gravity", f"0 0 {-params.gravity!r}")
    # Frame and rider share the rear body's centre of mass; inertia splits with mass.
    inertia = np.array([9.2, 11.0, 2.8, 0.0, -2.4, 0.0])
    for body, mass in (("frame", REAR_BODY_MASS - params.rider_mass), ("rider", params.rider_mass)):
        root.find(f".//body[@name='{body}']/inertial").attrib.update(
            mass=repr(mass), fullinertia=" ".join(repr(float(v)) for v in inertia * mass / REAR_BODY_MASS)
        )
    weight = cg_force_per_metre(params)
    for name, sign in (("cg_left", -1.0), ("cg_right", 1.0)):
        root.find(f".//motor[@name='{name}']").set("gear", f"0 0 {sign * weight!r} 0 0 0")
    for name, radius in (("rear_tyre", REAR_RADIUS), ("front_tyre", FRONT_RADIUS)):
        root.find(f".//geom[@name='{name}']").set("size", f"{radius!r} {params.tyre_half_width!r} {radius!r}")
    tyre = root.find(".//default[@class='tyre']/geom")
    tyre.set("friction", f"{params.tyre_friction!r} 0 0")
    root.find(".//geom[@name='floor']").set("friction", f"{params.tyre_friction!r} 0 0")
    return ET.tostring(root, encoding="unicode"), assets


def cg_force_per_metre(params: BicycleParams | None = None) -> float:
    """Force (N) per metre of rider CG offset at each site of the couple: m g / (2 L).

    The forces -+ f d (world z) at the points L to the left and right of the
    rider's centre of mass make the couple d y x (-m g z), the moment by which
    the rider's weight moved d along the frame's y axis differs from it centred.
    """
    params = params or BicycleParams()
    return params.rider_mass * params.gravity / (2.0 * CG_ARM)


# --- Geometry of the upright-ish bicycle (vectorised) -------------------------


def _rotate_axis(v: np.ndarray, axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotates the fixed vector ``v`` about unit ``axis`` by each ``angle`` (Rodrigues)."""
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    return v * c + np.cross(axis, v) * s + axis * np.dot(axis, v) * (1.0 - c)


def _frame_to_world(v: np.ndarray, roll: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """Applies R = Rx(roll) Ry(pitch) (heading +x) to rows of ``v``."""
    cp, sp = np.cos(pitch), np.sin(pitch)
    x = v[:, 0] * cp + v[:, 2] * sp
    z = -v[:, 0] * sp + v[:, 2] * cp
    cr, sr = np.cos(roll), np.sin(roll)
    return np.stack([x, v[:, 1] * cr - z * sr, v[:, 1] * sr + z * cr], axis=1)


def _front_points(roll: np.ndarray, pitch: np.ndarray, steer: np.ndarray) -> dict[str, np.ndarray]:
    """World points and axes of the bicycle with its rear contact at the origin."""
    centre = _STEER_POINT + _rotate_axis(_FRONT_CENTRE - _STEER_POINT, _STEER_AXIS, steer)
    axle = _rotate_axis(_Y, _STEER_AXIS, steer)
    rear_centre = np.stack([np.zeros_like(roll), -REAR_RADIUS * np.sin(roll), REAR_RADIUS * np.cos(roll)], axis=1)
    front_centre = rear_centre + _frame_to_world(centre, roll, pitch)
    front_axle = _frame_to_world(axle, roll, pitch)
    shape = centre.shape
    # The knife edge touches the floor at the rim point lowest along -z.
    down = _Z - front_axle[:, 2:3] * front_axle
    down /= np.linalg.norm(down, axis=1, keepdims=True)
    return {
        "rear_centre": rear_centre,
        "front_centre": front_centre,
        "front_axle": front_axle,
        "front_contact": front_centre - FRONT_RADIUS * down,
        "steer_point": rear_centre + _frame_to_world(np.broadcast_to(_STEER_POINT, shape), roll, pitch),
        "steer_axis": _frame_to_world(np.broadcast_to(_STEER_AXIS, shape), roll, pitch),
    }


def frame_pitch(roll: np.ndarray, steer: np.ndarray) -> np.ndarray:
    """Pitch of the rear frame (rad, nose down positive) that keeps both tyres on the floor.

    The benchmark's holonomic constraint: given roll and steer angles (arrays of
    the same shape), the pitch at which the front knife edge touches the floor
    when the rear one does. Zero when upright and straight.
    """
    roll, steer = np.broadcast_arrays(np.asarray(roll, np.float64), np.asarray(steer, np.float64))
    shape = roll.shape
    roll, steer = roll.ravel(), steer.ravel()

    def height(r: np.ndarray, p: np.ndarray, s: np.ndarray) -> np.ndarray:
        return _front_points(r, p, s)["front_contact"][:, 2]

    # Newton's method, each entry stopped as soon as it has converged, so that
    # an entry's pitch does not depend on the others in the batch (a batched
    # scipy.optimize.newton iterates every entry until all have converged, which
    # moves the last bits): the sampler's many starts then equal single resets.
    pitch = np.zeros_like(roll)
    active = np.arange(len(roll))
    for _ in range(_PITCH_MAX_ITERATIONS):
        if not len(active):
            break
        r, p, s = roll[active], pitch[active], steer[active]
        slope = (height(r, p + _PITCH_DELTA, s) - height(r, p - _PITCH_DELTA, s)) / (2 * _PITCH_DELTA)
        step = height(r, p, s) / slope
        pitch[active] = p - step
        active = active[np.abs(step) > _PITCH_TOLERANCE]
    if len(active):
        raise RuntimeError(f"frame pitch did not converge for roll {roll[active]}, steer {steer[active]}")
    return pitch.reshape(shape)


class Physics(common.StatePhysics):
    """Bicycle physics with the paper's state ``[theta, theta_dot, omega, omega_dot]``."""

    STATE_SIZE = 4

    def joint_address(self, joint: str) -> tuple[int, int]:
        """(qpos address, dof address) of a joint."""
        # Looked up once: name2id costs ~20 us, and states_from runs every step.
        addresses = self.__dict__.setdefault("_joint_addresses", {})
        if joint not in addresses:
            joint_id = self.model.name2id(joint, "joint")
            addresses[joint] = int(self.model.jnt_qposadr[joint_id]), int(self.model.jnt_dofadr[joint_id])
        return addresses[joint]

    def states_from(self, qpos: np.ndarray, qvel: np.ndarray) -> np.ndarray:
        qpos, qvel = np.atleast_2d(np.asarray(qpos, np.float64)), np.atleast_2d(np.asarray(qvel, np.float64))
        root_q, root_v = self.joint_address("root")
        steer_q, steer_v = self.joint_address("steer")
        w, x, y, z = (qpos[:, root_q + 3 + i] for i in range(4))
        norm2 = w * w + x * x + y * y + z * z
        # Rows of the rotation matrix's third row (world z of the body axes).
        r20 = 2.0 * (x * z - w * y) / norm2
        r21 = 2.0 * (y * z + w * x) / norm2
        r22 = 1.0 - 2.0 * (x * x + y * y) / norm2
        # minimum/maximum, not clip: the same numbers for a fifth of the call's overhead
        roll = np.arcsin(np.minimum(np.maximum(r21, -1.0), 1.0))
        # d(r21)/dt = (omega_world x body_y) . z, with body-frame angular velocity.
        wx, wz = qvel[:, root_v + 3], qvel[:, root_v + 5]
        roll_rate = (r22 * wx - r20 * wz) / np.sqrt(np.maximum(1.0 - r21 * r21, 1e-300))
        out = np.empty((len(qpos), 4))
        out[:, 0], out[:, 1], out[:, 2], out[:, 3] = qpos[:, steer_q], qvel[:, steer_v], roll, roll_rate
        return out

    def qpos_qvel_from(self, states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Puts the bicycle at the origin heading +x, both tyres on the floor, rolling without slip.

        The rear contact moves forward at :meth:`target_speed`; the frame pitch, yaw
        rate and wheel rates follow from the rolling constraints.
        """
        s = np.atleast_2d(np.asarray(states, np.float64))
        n = len(s)
        steer, steer_rate, roll, roll_rate = s.T
        pitch = frame_pitch(roll, steer)
        pts = _front_points(roll, pitch, steer)
        speed = self.target_speed()
        rear_axle = np.stack([np.zeros(n), np.cos(roll), np.sin(roll)], axis=1)
        # Rear contact at rest: the rear centre moves forward at speed and sideways with roll.
        sideways = -roll_rate * REAR_RADIUS
        rear_velocity = np.stack([np.full(n, speed), sideways * np.cos(roll), sideways * np.sin(roll)], axis=1)
        # Frame angular velocity = yaw_rate z + roll_rate x + pitch_rate rear_axle.
        # The front contact's material velocity must vanish: 3 equations for
        # yaw rate, pitch rate and the front wheel's spin.
        to_contact = pts["front_contact"] - pts["rear_centre"]
        x_axis = np.broadcast_to([1.0, 0.0, 0.0], (n, 3))
        known = (
            rear_velocity
            + roll_rate[:, None] * np.cross(x_axis, to_contact)
            + steer_rate[:, None] * np.cross(pts["steer_axis"], pts["front_contact"] - pts["steer_point"])
        )
        columns = np.stack(
            [
                np.cross(np.broadcast_to(_Z, (n, 3)), to_contact),
                np.cross(rear_axle, to_contact),
                np.cross(pts["front_axle"], pts["front_contact"] - pts["front_centre"]),
            ],
            axis=2,
        )
        yaw_rate, pitch_rate, front_spin = np.linalg.solve(columns, -known[:, :, None])[:, :, 0].T
        rear_spin = speed / REAR_RADIUS - pitch_rate - yaw_rate * np.sin(roll)

        half_r, half_p = roll / 2.0, pitch / 2.0
        quat = np.stack(
            [
                np.cos(half_r) * np.cos(half_p),
                np.sin(half_r) * np.cos(half_p),
                np.cos(half_r) * np.sin(half_p),
                np.sin(half_r) * np.sin(half_p),
            ],
            axis=1,
        )
        omega_world = yaw_rate[:, None] * _Z + roll_rate[:, None] * x_axis + pitch_rate[:, None] * rear_axle
        # Free joints take angular velocity in the body frame: R^T omega, R = Rx Ry.
        cr, sr = np.cos(roll), np.sin(roll)
        ox, oy = omega_world[:, 0], omega_world[:, 1] * cr + omega_world[:, 2] * sr
        oz = -omega_world[:, 1] * sr + omega_world[:, 2] * cr
        cp, sp = np.cos(pitch), np.sin(pitch)
        omega_body = np.stack([ox * cp - oz * sp, oy, ox * sp + oz * cp], axis=1)

        qpos = np.zeros((n, self.model.nq))
        qvel = np.zeros((n, self.model.nv))
        root_q, root_v = self.joint_address("root")
        qpos[:, root_q : root_q + 3] = pts["rear_centre"]
        qpos[:, root_q + 3 : root_q + 7] = quat
        qvel[:, root_v : root_v + 3] = rear_velocity
        qvel[:, root_v + 3 : root_v + 6] = omega_body
        for joint, angle, rate in (
            ("steer", steer, steer_rate),
            ("rear_wheel", 0.0, rear_spin),
            ("front_wheel", 0.0, front_spin),
        ):
            q, v = self.joint_address(joint)
            qpos[:, q], qvel[:, v] = angle, rate
        return qpos, qvel

    def target_speed(self) -> float:
        """Forward speed (m/s) that ``set_state_vector`` gives the bicycle (the task's ``speed``)."""
        return float(self.model.numeric_data[self.model.numeric_adr[self.model.name2id("speed", "numeric")]])

    def set_target_speed(self, speed: float) -> None:
        """Sets the forward speed (m/s) used by ``set_state_vector``."""
        self.model.numeric_data[self.model.numeric_adr[self.model.name2id("speed", "numeric")]] = speed

    def steer_angle(self) -> float:
        """theta (rad), positive steering right."""
        return float(self.named.data.qpos["steer"][0])

    def steer_rate(self) -> float:
        """theta_dot (rad/s)."""
        return float(self.named.data.qvel["steer"][0])

    def roll_angle(self) -> float:
        """omega (rad) from vertical, positive leaning right."""
        return float(self.state_vector()[2])

    def roll_rate(self) -> float:
        """omega_dot (rad/s)."""
        return float(self.state_vector()[3])

    def forward_speed(self) -> float:
        """Speed of the rear wheel centre along the heading (m/s).

        The heading is where the rear wheel's plane meets the floor: axle x up.
        """
        axle = self.named.data.xmat["frame"].reshape(3, 3)[:, 1]
        heading = np.cross(axle, _Z)
        heading /= np.linalg.norm(heading)
        return float(np.dot(self.named.data.qvel["root"][:3], heading))

    def cg_offset(self) -> float:
        """Rider's centre-of-gravity offset acting this step (m, positive to the left)."""
        return float(self.named.data.ctrl["cg_left"])

    def steer_torque(self) -> float:
        """Handlebar torque the actuator applies now (N m), after clipping."""
        return float(self.named.data.actuator_force["steer_torque"])


def control_vector(torque: Any, cg_offset: Any, speed: Any) -> np.ndarray:
    """(N, 4) ctrl rows: handlebar torque (N m), CG offset d (m) twice, speed set-point (m/s;
    one for all rows, or one a row)."""
    torque, cg_offset = np.broadcast_arrays(
        np.atleast_1d(np.asarray(torque, np.float64)), np.atleast_1d(np.asarray(cg_offset, np.float64))
    )
    speeds = np.broadcast_to(np.asarray(speed, np.float64), torque.shape)
    return np.column_stack([torque, cg_offset, cg_offset, speeds])


class Task(common.StateTask):
    """Keep the bicycle within 12 degrees of upright at a constant forward speed."""

    def __init__(
        self,
        speed: float = DEFAULT_SPEED,
        cg_noise: float = DEFAULT_CG_NOISE,
        random: Any = None,
        start_roll: float = START_ROLL,
    ):
        speed, cg_noise = common.real(speed, "bicycle speed"), common.real(cg_noise, "bicycle cg_noise")
        start_roll = common.real(start_roll, "bicycle start_roll")
        if not (math.isfinite(start_roll) and 0.0 <= start_roll < ROLL_LIMIT):
            raise ValueError(f"start_roll must be in [0, {ROLL_LIMIT:.4f}) rad (below the fall), got {start_roll!r}")
        self.start_roll = start_roll
        if not (math.isfinite(speed) and 0.0 < speed <= 20.0):
            raise ValueError(f"speed must be in (0, 20] m/s, got {speed!r}")
        if not (math.isfinite(cg_noise) and 0.0 <= cg_noise <= MAX_CG_NOISE):
            raise ValueError(f"cg_noise must be in [0, {MAX_CG_NOISE}] m, got {cg_noise!r}")
        self.speed = speed
        self.cg_noise = cg_noise
        super().__init__(random=random)

    def action_spec(self, physics: Physics) -> specs.BoundedArray:
        return specs.BoundedArray(
            shape=(1,),
            dtype=np.float64,
            minimum=[-TORQUE_LIMIT],
            maximum=[TORQUE_LIMIT],
            name="steer_torque",
        )

    @property
    def control_noise(self) -> bool:
        return self.cg_noise > 0

    def controls(self, action_values: np.ndarray, random: Any) -> np.ndarray:
        torque = np.asarray(action_values, np.float64).reshape(-1, 1)
        n = len(torque)
        # No noise, no draws: start states then do not depend on how many
        # steps were taken between resets (the sampler's lockstep episodes).
        # A new offset every control step (Randlov & Alstrom 1998): i.i.d. noise
        # on the transition, carried by ctrl alone, so the batched sampler and
        # mujoco.rollout replay episodes exactly.
        offset = random.uniform(-self.cg_noise, self.cg_noise, size=n) if self.cg_noise else np.zeros(n)
        return control_vector(torque[:, 0], offset, self.speed)

    def controls_each(
        self, action_values: np.ndarray, randoms: Sequence[Any], context: Mapping[str, np.ndarray] | None = None
    ) -> np.ndarray:
        """``controls`` of each row with its own random stream: row i is what
        ``controls(action_values[i : i + 1], randoms[i])`` gives, drawing the same
        numbers from ``randoms[i]``, for all rows in one call (evaluation episodes).

        ``context``: per-row ``cg_noise`` and ``speed`` (a vector env's contexts),
        row i then being what a task with row i's values gives.
        """
        torque = np.asarray(action_values, np.float64).reshape(-1, 1)
        if len(randoms) != len(torque):
            raise ValueError(f"controls_each needs one random stream per row, got {len(randoms)} for {len(torque)}")
        context = context or {}
        speed = context.get("speed", self.speed)
        if "cg_noise" not in context:
            if not self.cg_noise:
                return control_vector(torque[:, 0], np.zeros(len(torque)), speed)
            c = self.cg_noise
            offset = np.concatenate([r.uniform(-c, c, size=1) for r in randoms]) if len(torque) else np.zeros(0)
            return control_vector(torque[:, 0], offset, speed)
        noise = context["cg_noise"]
        offset = np.zeros(len(torque))
        for j in np.flatnonzero(noise):  # a row without noise draws nothing, as its task would
            offset[j] = randoms[j].uniform(-noise[j], noise[j], size=1)[0]
        return control_vector(torque[:, 0], offset, speed)

    def start_configurations(self, physics: Physics, n: int) -> tuple[np.ndarray, np.ndarray]:
        physics.set_target_speed(self.speed)  # qpos_qvel_from reads it
        states = np.zeros((n, Physics.STATE_SIZE))
        states[:, 2] = self.random.uniform(-self.start_roll, self.start_roll, size=n)
        return physics.qpos_qvel_from(states)

    def initialize_episode(self, physics: Physics) -> None:
        super().initialize_episode(physics)
        physics.data.ctrl[:] = control_vector(0.0, 0.0, self.speed)[0]

    def batch_absorbing(self, states: np.ndarray) -> np.ndarray:
        return np.abs(np.asarray(states, np.float64)[:, 2]) > ROLL_LIMIT

    def batch_reward(self, states: np.ndarray) -> np.ndarray:
        return np.where(self.batch_absorbing(states), 0.0, 1.0)


def balance(
    time_limit: float = DEFAULT_TIME_LIMIT,
    random: Any = None,
    environment_kwargs: dict[str, Any] | None = None,
    speed: float = DEFAULT_SPEED,
    cg_noise: float = DEFAULT_CG_NOISE,
    params: BicycleParams | None = None,
    start_roll: float = START_ROLL,
) -> common.Environment:
    """Bicycle balance at ``speed`` m/s with rider noise up to ``cg_noise`` m, each episode
    starting upright but for a roll uniform in +-``start_roll`` rad (default 1 degree)."""
    task = Task(speed=speed, cg_noise=cg_noise, random=random, start_roll=start_roll)
    physics = common.compile_physics(Physics, *model_xml(params))
    physics.set_target_speed(task.speed)
    return common.Environment(
        physics,
        task,
        time_limit=time_limit,
        control_timestep=CONTROL_TIMESTEP,
        **(environment_kwargs or {}),
    )


TASKS = {"balance": balance}

CONTEXTS = {
    "balance": ContextSpec(
        (
            ContextKey("speed", "m/s", 0.1, 20.0, "task", "forward speed the rear servo holds"),
            ContextKey("cg_noise", "m", 0.0, MAX_CG_NOISE, "task", "rider CG offset drawn each step, up to"),
            ContextKey("start_roll", "rad", 0.0, 0.2, "task", "start roll drawn within +-"),
            ContextKey("rider_mass", "kg", 1.0, 84.0, "model", "rider's share of the 85 kg rear body", True),
            ContextKey("tyre_friction", "-", 0.1, 3.0, "model", "tyre-floor sliding friction", True),
            ContextKey("gravity", "m/s^2", 0.1, 30.0, "model", "gravitational acceleration", True),
        ),
        BicycleParams,
    )
}
"""Context keys (``tatl_mj.suite.contexts``); the model keys are compiled into the MJCF model,
so a vector env builds the model of each distinct value."""


def describe(task: str, **_: Any) -> TaskDescription:
    """The bicycle's static facts (see ``tatl_mj.description``)."""
    return TaskDescription(
        domain="bicycle",
        task=task,
        dynamics_version=DYNAMICS_VERSION,
        state_names=("steer", "steer_rate", "roll", "roll_rate"),
        periodic=(False,) * 4,
        action_values=ACTIONS,
        discrete=False,
        control_timestep=CONTROL_TIMESTEP,
        action_low=np.array([-TORQUE_LIMIT]),
        action_high=np.array([TORQUE_LIMIT]),
        # Upright to the fall, and about the steer and rates random-policy episodes reach.
        reset_low=np.array([-0.5, -1.5, -ROLL_LIMIT, -1.5]),
        reset_high=np.array([0.5, 1.5, ROLL_LIMIT, 1.5]),
        steadiness=("roll",),
        falls=True,
    )
