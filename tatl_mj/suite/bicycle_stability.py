"""The bicycle's linear stability, measured on the MuJoCo model: its lateral eigenvalues and
the speeds between which it balances itself (the benchmark of Meijaard et al. 2007;
docs/bicycle.md compares them). An analysis of the model, apart from the task."""

from __future__ import annotations

import math

import mujoco
import numpy as np
from scipy import optimize

from tatl_mj.suite import common
from tatl_mj.suite.bicycle import BicycleParams, Physics, control_vector, model_xml


def lateral_eigenvalues(speed: float, params: BicycleParams | None = None, settle: float = 0.5) -> np.ndarray:
    """Eigenvalues (1/s) of the MuJoCo bicycle's lateral motion rolling straight at ``speed``.

    The bicycle runs upright and uncontrolled for ``settle`` s (the rear servo
    holds ``speed``), then MuJoCo's finite-difference linearisation of one physics
    step (``mjd_transitionFD``, centred) gives the discrete map, whose eigenvalues
    mu become ``log(mu) / timestep``. Kept: the benchmark's modes (weave, capsize,
    castor); dropped: neutral directions (position, yaw, wheel angles,
    |lambda| < 2e-5), the speed servo's mode and contact modes (|lambda| > 40).
    Sorted by real part.
    """
    if not (math.isfinite(speed) and speed > 0):
        raise ValueError(f"speed must be a positive number of m/s, got {speed!r}")
    physics = common.compile_physics(Physics, *model_xml(params))
    physics.set_target_speed(speed)
    model, data = physics.model.ptr, physics.data.ptr
    qpos, qvel = physics.qpos_qvel_from(np.zeros((1, Physics.STATE_SIZE)))
    data.qpos[:], data.qvel[:], data.ctrl[:] = qpos[0], qvel[0], control_vector(0.0, 0.0, speed)[0]
    for _ in range(int(round(settle / model.opt.timestep))):
        mujoco.mj_step(model, data)
    transition = np.zeros((2 * model.nv + model.na, 2 * model.nv + model.na))
    mujoco.mjd_transitionFD(model, data, 1e-6, True, transition, None, None, None)
    mu, vectors = np.linalg.eig(transition)
    lam = np.log(mu.astype(complex)) / model.opt.timestep
    _, root_v = physics.joint_address("root")
    _, rear_v = physics.joint_address("rear_wheel")
    forward = np.abs(vectors[model.nv + root_v]) + np.abs(vectors[model.nv + rear_v])
    keep = (np.abs(lam) > 2e-5) & (np.abs(lam) < 40.0) & (forward < 0.5)
    lam = lam[keep]
    return lam[np.argsort(lam.real)]


def weave_growth(speed: float, params: BicycleParams | None = None) -> float:
    """Real part (1/s) of the weave (the oscillatory lateral mode) at ``speed``."""
    lam = lateral_eigenvalues(speed, params)
    return float(lam[np.abs(lam.imag) > 1e-2].real.max())


def capsize_growth(speed: float, params: BicycleParams | None = None) -> float:
    """Largest real lateral eigenvalue (1/s) at ``speed``: the capsize mode above the weave speed."""
    lam = lateral_eigenvalues(speed, params)
    return float(lam[np.abs(lam.imag) <= 1e-2].real.max())


def stability_window(
    params: BicycleParams | None = None,
    weave_bracket: tuple[float, float] = (3.0, 5.5),
    capsize_bracket: tuple[float, float] = (5.0, 8.0),
) -> tuple[float, float]:
    """(weave speed, capsize speed) in m/s: where the weave and capsize modes cross zero.

    The benchmark bicycle is self-stable between them (4.292 and 6.024 m/s in
    Meijaard et al. 2007). Each bracket must hold one sign change.
    """
    weave = optimize.brentq(lambda v: weave_growth(v, params), *weave_bracket, xtol=1e-4)
    capsize = optimize.brentq(lambda v: capsize_growth(v, params), *capsize_bracket, xtol=1e-4)
    return float(weave), float(capsize)
