"""Cart-pole balance: a pole hinged on a cart that a horizontal force moves along a rail.

The classic problem (Barto, Sutton & Anderson 1983) with Gymnasium's constants,
simulated by MuJoCo. The paper's source task for the bicycle.

=================  ==========================================================
State              ``[x, x_dot, theta, theta_dot]`` (float64)
                   x: cart position along the rail (m), 0 at the centre;
                   x_dot: cart velocity (m/s);
                   theta: pole angle from upright (rad), positive when the pole
                   leans towards +x (not wrapped; the episode ends long before
                   it would matter);
                   theta_dot: pole angular velocity (rad/s).
Actions            ``ACTIONS = [[-20], [0], [20]]``: horizontal force on the
                   cart (N, positive pushes towards +x). The actuator accepts
                   any force in +-``force_limit`` (default 20 N); larger values
                   are clipped by MuJoCo.
Reward             +1 for every step that ends in a non-failed state, 0 on the
                   failing step.
Start state        every state entry uniform in [-0.05, 0.05], from the task's
                   ``random``.
Episode end        failure, with discount 0: ``|theta| > 12 deg`` or
                   ``|x| > 2.4 m``; otherwise the time limit (default 10 s =
                   500 steps), which is not a failure.
Timing             control step 0.02 s; physics step 0.01 s (RK4), so two
                   physics steps per action.
Parameters         :class:`CartPoleParams`: cart_mass 1.0 kg, pole_mass 0.1 kg,
                   pole_half_length 0.5 m (uniform rod, inertia about its
                   centre ``m l^2 / 3``), gravity 9.8 m/s^2, force_limit 20 N.
=================  ==========================================================

Equations (no friction), with M the cart mass, m, l, I the pole's mass,
centre-of-mass distance from the hinge and inertia about its centre::

    (M + m) x_dd + m l cos(theta) theta_dd - m l sin(theta) theta_d^2 = F
    m l cos(theta) x_dd + (I + m l^2) theta_dd - m g l sin(theta)       = 0
"""

from __future__ import annotations

import dataclasses
import math
import xml.etree.ElementTree as ET
from typing import Any

import numpy as np

from tatl_mj.description import TaskDescription
from tatl_mj.suite import common
from tatl_mj.suite.contexts import ContextKey, ContextSpec

CONTROL_TIMESTEP = 0.02  # s, Gymnasium's tau
DEFAULT_TIME_LIMIT = 10.0  # s, 500 control steps
THETA_LIMIT = math.radians(12.0)  # rad
X_LIMIT = 2.4  # m
START_HALF_WIDTH = 0.05  # every state entry starts uniform in +-0.05

ACTIONS = np.array([[-20.0], [0.0], [20.0]])
DYNAMICS_VERSION = 1  # of every task here; docs/versions.md says when it is bumped
# The camera clips film from (tatl_mj.render): side-on, following the cart, so the pole
# swings in the image plane and fills the frame ("fixed" shows the whole rail, small).
CAMERA = "tracking"


@dataclasses.dataclass(frozen=True)
class CartPoleParams:
    """Physical parameters of the cart-pole; non-physical values raise ValueError."""

    cart_mass: float = common.positive(1.0, "cart mass (kg)")
    pole_mass: float = common.positive(0.1, "pole mass (kg), a uniform rod")
    pole_half_length: float = common.positive(0.5, "hinge to pole centre of mass (m)")
    gravity: float = common.positive(9.8, "gravitational acceleration (m/s^2)")
    force_limit: float = common.positive(20.0, "largest force the actuator applies (N)")

    def __post_init__(self) -> None:
        common.check_params(self)


def model_xml(params: CartPoleParams | None = None) -> tuple[str, dict[str, bytes]]:
    """The MJCF text (with ``params`` written in) and its include files."""
    if params is None:
        return common.read_model("cartpole.xml")
    root, assets = common.parse_model("cartpole.xml", params, CartPoleParams)
    m, l = params.pole_mass, params.pole_half_length
    rod_inertia = m * l * l / 3.0  # uniform rod of length 2l about its centre
    root.find("option").set("gravity", f"0 0 {-params.gravity!r}")
    root.find(".//body[@name='cart']/inertial").set("mass", repr(params.cart_mass))
    pole = root.find(".//body[@name='pole']")
    pole.find("inertial").attrib.update(
        pos=f"0 0 {l!r}", mass=repr(m), diaginertia=f"{rod_inertia!r} {rod_inertia!r} 1e-6"
    )
    pole.find("geom[@name='pole']").set("fromto", f"0 0 0 0 0 {2 * l!r}")
    root.find(".//motor[@name='force']").set("ctrlrange", f"{-params.force_limit!r} {params.force_limit!r}")
    return ET.tostring(root, encoding="unicode"), assets


class Physics(common.StatePhysics):
    """Cart-pole physics with the paper's state ``[x, x_dot, theta, theta_dot]``."""

    STATE_SIZE = 4

    def states_from(self, qpos: np.ndarray, qvel: np.ndarray) -> np.ndarray:
        # qpos = [slider, hinge], qvel likewise: the state interleaves them.
        qpos, qvel = np.asarray(qpos, np.float64), np.asarray(qvel, np.float64)
        # Column copies, not a concatenation and a fancy index: a third of the time
        # (a horizon controller's source queries call this ten times a decision).
        out = np.empty((len(qpos), 4))
        out[:, 0], out[:, 1], out[:, 2], out[:, 3] = qpos[:, 0], qvel[:, 0], qpos[:, 1], qvel[:, 1]
        return out

    def qpos_qvel_from(self, states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s = np.asarray(states, np.float64)
        return s[:, 0::2].copy(), s[:, 1::2].copy()

    def cart_position(self) -> float:
        """x (m)."""
        return float(self.named.data.qpos["slider"][0])

    def cart_velocity(self) -> float:
        """x_dot (m/s)."""
        return float(self.named.data.qvel["slider"][0])

    def pole_angle(self) -> float:
        """theta (rad) from upright, positive towards +x."""
        return float(self.named.data.qpos["hinge"][0])

    def pole_angular_velocity(self) -> float:
        """theta_dot (rad/s)."""
        return float(self.named.data.qvel["hinge"][0])

    def cart_force(self) -> float:
        """The force the actuator applies now (N), after clipping to the limit."""
        return float(self.named.data.actuator_force["force"])


class Task(common.StateTask):
    """Keep the pole within 12 degrees of upright and the cart within 2.4 m."""

    def start_configurations(self, physics: Physics, n: int) -> tuple[np.ndarray, np.ndarray]:
        # Row-major: the same draws, in the same order, as n draws of one state.
        states = self.random.uniform(-START_HALF_WIDTH, START_HALF_WIDTH, size=(n, Physics.STATE_SIZE))
        return physics.qpos_qvel_from(states)

    def batch_absorbing(self, states: np.ndarray) -> np.ndarray:
        s = np.asarray(states, np.float64)
        return (np.abs(s[:, 2]) > THETA_LIMIT) | (np.abs(s[:, 0]) > X_LIMIT)

    def batch_reward(self, states: np.ndarray) -> np.ndarray:
        return np.where(self.batch_absorbing(states), 0.0, 1.0)


def balance(
    time_limit: float = DEFAULT_TIME_LIMIT,
    random: Any = None,
    environment_kwargs: dict[str, Any] | None = None,
    params: CartPoleParams | None = None,
) -> common.Environment:
    """Cart-pole balance; ``params`` changes the physical constants."""
    physics = common.compile_physics(Physics, *model_xml(params))
    return common.Environment(
        physics,
        Task(random=random),
        time_limit=time_limit,
        control_timestep=CONTROL_TIMESTEP,
        **(environment_kwargs or {}),
    )


TASKS = {"balance": balance}

CONTEXTS = {
    "balance": ContextSpec(
        (
            ContextKey("cart_mass", "kg", 0.1, 10.0, "model", "cart mass", True),
            ContextKey("pole_mass", "kg", 0.01, 5.0, "model", "pole mass, a uniform rod", True),
            ContextKey("pole_half_length", "m", 0.05, 5.0, "model", "hinge to pole centre of mass", True),
            ContextKey("gravity", "m/s^2", 0.1, 30.0, "model", "gravitational acceleration", True),
        ),
        CartPoleParams,
    )
}
"""Context keys (``tatl_mj.suite.contexts``); ``force_limit`` is not one: it sets the action space."""


def describe(task: str, params: CartPoleParams | None = None, **_: Any) -> TaskDescription:
    """The cart-pole's static facts (see ``tatl_mj.description``)."""
    limit = (params or CartPoleParams()).force_limit
    return TaskDescription(
        domain="cartpole",
        task=task,
        dynamics_version=DYNAMICS_VERSION,
        state_names=("x", "x_dot", "theta", "theta_dot"),
        periodic=(False,) * 4,
        action_values=ACTIONS,
        discrete=False,
        control_timestep=CONTROL_TIMESTEP,
        action_low=np.array([-limit]),
        action_high=np.array([limit]),
        # The track and the pole's fall angle, with the rates the source's FQI box covers.
        reset_low=np.array([-X_LIMIT, -2.0, -THETA_LIMIT, -2.0]),
        reset_high=np.array([X_LIMIT, 2.0, THETA_LIMIT, 2.0]),
        falls=True,
        gymnasium_peer="CartPole-v1" if task == next(iter(TASKS)) else None,
    )
