"""Raw physics speed: ``mujoco.rollout`` of a task's bare model, the yardstick a run's work is
set against (``tatl run``'s physics line) and ``tatl bench`` compares the sampler with."""

from __future__ import annotations

import time
from typing import Any

import numpy as np


def time_rollout(domain: str, task: str, seconds: float, threads: int, seed: int = 0) -> dict[str, Any]:
    """Raw ``mujoco.rollout``: the bare model, open loop, constant control per control step."""
    import mujoco
    import mujoco.rollout

    from tatl_mj import suite

    env = suite.load(domain, task, task_kwargs={"random": seed})
    physics = env.physics
    model = physics.model.ptr
    n_sub = int(round(env.control_timestep() / physics.timestep()))
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    n_batch = 256
    starts = np.empty((n_batch, mujoco.mj_stateSize(model, spec)))
    for row in starts:
        env.reset()
        mujoco.mj_getState(model, physics.data.ptr, row, spec)
    rng = np.random.default_rng(seed)
    actions = np.asarray(suite.action_set(domain), np.float64)
    # Full control vectors (a task may add set-points, e.g. rider noise and speed).
    controls = env.task.controls(actions, env.task.random)
    return timed_rollouts(model, starts, controls, n_sub, seconds, threads, rng)


def timed_rollouts(
    model: Any, starts: np.ndarray, controls: np.ndarray, n_sub: int, seconds: float, threads: int, rng: Any
) -> dict[str, Any]:
    """``mujoco.rollout`` of ``len(starts)`` rows from ``starts`` for about ``seconds``, each control
    step a uniform pick among ``controls`` (``(actions, nu)`` for every row, or ``(rows, actions,
    nu)`` a row), held for ``n_sub`` substeps; ``model`` one model or one a row."""
    import mujoco
    import mujoco.rollout

    n_rows = len(starts)
    first = model[0] if isinstance(model, (list, tuple)) else model
    rows = np.arange(n_rows)[:, None]
    datas = [mujoco.MjData(first) for _ in range(max(threads, 1))]
    with mujoco.rollout.Rollout(nthread=threads) as pool:

        def run(n_control: int) -> float:
            picks = rng.integers(controls.shape[-2], size=(n_rows, n_control))
            chosen = controls[picks] if controls.ndim == 2 else controls[rows, picks]
            ctrl = np.repeat(chosen, n_sub, axis=1)
            begin = time.perf_counter()
            pool.rollout(model, datas, starts, ctrl)
            return time.perf_counter() - begin

        pilot = 10
        rate = n_rows * pilot / run(pilot)
        n_control = max(pilot, int(rate * seconds / n_rows))
        elapsed = run(n_control)
    steps = n_rows * n_control
    return {"steps": steps, "seconds": elapsed, "steps_per_s": steps / elapsed, "substeps": n_sub}


__all__ = ["time_rollout", "timed_rollouts"]
