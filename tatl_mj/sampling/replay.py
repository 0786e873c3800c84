"""One control step of a task replayed from a state saved during an episode, as a function of the action.

What the theorem's premises ask of the target (``tatl_mj.transfer.premises``: its
control matrix B(s) by finite differences, how affine its step is in the action)
needs the very step an episode took, taken again with other actions. The paper
state does not determine that step: the bicycle's observation leaves out its
position, heading, wheel angles and the contact solver's warm start, the
time-varying pendulum's model depends on the step's index, and the bicycle's
rider draws a new offset every step. A :class:`Visit` keeps all three: the whole
MuJoCo state (``mj_getState`` with ``mjSTATE_INTEGRATION``, a superset of
``mjSTATE_FULLPHYSICS``: time, qpos, qvel, act, warm start, ctrl and the applied
forces; the row a ``mujoco.batch.Batch`` steps), the step index, and the random
stream the step's controls draw from, as it stood before the step.

:func:`control_step` turns a visit into ``step(action) -> next paper state``.
Every call restores the state into a scratch MjData, re-draws the same noise
from a fresh copy of the saved stream, gives the model the visit's step
(``model_for_step``), and takes the step's ``n_sub`` MuJoCo steps with the
control held, as ``Simulator.advance`` does: the action is the only thing that
varies between calls, and the environment's own state is left alone.
"""

from __future__ import annotations

import copy
import dataclasses
from typing import Any, Callable

import mujoco
import numpy as np

from tatl_mj.validation import integer

_INTEGRATION = mujoco.mjtState.mjSTATE_INTEGRATION.value

ControlStep = Callable[[np.ndarray], np.ndarray]
"""``step(action (m,)) -> (d,)`` the paper state after one control step (NaN where MuJoCo warned)."""


@dataclasses.dataclass(frozen=True, eq=False)
class Visit:
    """What one control step of an episode depends on besides its action.

    Attributes:
      state: the simulation's ``mjSTATE_INTEGRATION`` state before the step.
      step: the step's index in its episode (0: the first after a reset).
      random: the stream the step's controls draw their noise from (a RandomState
        or a Generator), as it stood before the step; copied on every use, never
        drawn from. None: the task's controls draw nothing.
    """

    state: np.ndarray
    step: int
    random: Any = None

    def __post_init__(self) -> None:
        # Checked, not converted: visit_of gives the state row MuJoCo wrote.
        state = self.state
        if not (isinstance(state, np.ndarray) and state.dtype == np.float64 and state.ndim == 1):
            raise ValueError(f"Visit.state must be a 1-D float64 array (mj_getState's row), got {state!r:.60}")
        if not np.all(np.isfinite(state)):
            raise ValueError("Visit.state must be finite")
        if type(self.step) is not int:
            raise ValueError(f"Visit.step must be an int, got {self.step!r}")
        integer("Visit", "step", self.step, 0)


def visit_of(physics: Any, step: int, random: Any = None) -> Visit:
    """The visit of ``physics``'s current state, before control step ``step`` (``random``
    copied now, so later draws from it do not move the visit's noise)."""
    model, data = physics.model.ptr, physics.data.ptr
    state = np.empty(mujoco.mj_stateSize(model, _INTEGRATION))
    mujoco.mj_getState(model, data, state, _INTEGRATION)
    return Visit(state, step, None if random is None else copy.deepcopy(random))


def substeps(env: Any) -> int:
    """MuJoCo steps in one control step of ``env``."""
    return int(round(env.control_timestep() / env.physics.timestep()))


def _rewinder(random: Any) -> Callable[[], Any]:
    """``rewind()`` -> a stream that draws what ``random`` draws next, on every call (a
    working copy set back to the saved state: a deep copy per call costs ten times as much)."""
    working = copy.deepcopy(random)
    if isinstance(random, np.random.RandomState):
        legacy = random.get_state()

        def rewind_legacy() -> Any:
            working.set_state(legacy)
            return working

        return rewind_legacy
    if isinstance(random, np.random.Generator):
        state = random.bit_generator.state

        def rewind() -> Any:
            working.bit_generator.state = state
            return working

        return rewind
    return lambda: copy.deepcopy(random)


def control_step(env: Any, visit: Visit, data: Any = None) -> ControlStep:
    """One control step of ``env``'s task from ``visit``, as a function of the action.

    ``env`` is a suite environment of the visit's task (its physics and task, not
    its live state, are used); tasks whose model depends on the step
    (``model_for_step``) have ``env``'s model edited into the visit's step's on
    every call, so give it an environment of its own. Where the task draws
    control noise, the visit must carry its stream. ``data``: a scratch
    ``mujoco.MjData`` of ``env``'s model to step in (each call overwrites it
    whole, so the steps of many visits may share one); None makes one.
    """
    physics, task = env.physics, env.task
    model = physics.model.ptr
    if visit.state.shape != (mujoco.mj_stateSize(model, _INTEGRATION),):
        size = mujoco.mj_stateSize(model, _INTEGRATION)
        raise ValueError(f"Visit.state has {visit.state.size} numbers; this task's MuJoCo state has {size}")
    noise = bool(getattr(task, "control_noise", False))
    if noise and visit.random is None:
        raise ValueError("this task's controls draw noise: the visit must carry the random stream they draw from")
    data = mujoco.MjData(model) if data is None else data
    n_sub = substeps(env)
    rewind = _rewinder(visit.random) if noise else None
    model_for_step = getattr(task, "model_for_step", None)

    def step(action: np.ndarray) -> np.ndarray:
        values = np.asarray(action, dtype=np.float64).reshape(1, -1)
        if model_for_step is not None:
            model_for_step(physics, visit.step)
        random = None if rewind is None else rewind()  # the same draws on every call
        mujoco.mj_setState(model, data, visit.state, _INTEGRATION)
        data.ctrl[:] = task.controls(values, random)[0]
        data.warning.number[:] = 0
        mujoco.mj_step(model, data, n_sub)
        if data.warning.number.any():  # dm_control's PhysicsError: the step diverged
            return np.full(physics.STATE_SIZE, np.nan)
        return physics.states_from(data.qpos[None], data.qvel[None])[0]

    return step


__all__ = ["ControlStep", "Visit", "control_step", "substeps", "visit_of"]
