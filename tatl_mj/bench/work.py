"""Fitting FQI, rendering frames and the memory of a large collection."""

from __future__ import annotations

import os
import resource
import time
import tracemalloc
from typing import Any

from tatl_mj.bench.machine import reference


def time_fqi(n: int, threads: int) -> dict[str, Any]:
    """Linear-RBF FQI (20 iterations) on ``n`` random cart-pole transitions."""
    from tatl_mj import sampling

    try:
        from tatl_mj.transfer import features, fqi
    except ImportError as error:
        return {"skipped": f"tatl_mj.transfer.fqi is not available: {error}"}
    tr = sampling.collect(*reference(), n, seed=0, n_threads=threads)
    basis = features.RBF.grid(
        low=[-2.4, -3.0, -0.21, -3.5],  # cart-pole's states under random actions
        high=[2.4, 3.0, 0.21, 3.5],
        n_centers=[3, 3, 5, 5],
        sigma=[1.2, 1.5, 0.05, 0.9],
    )
    start = time.perf_counter()
    fqi.fitted_q_iteration(tr, 3, fqi.LinearRegressor(basis), gamma=0.99, iterations=20)
    elapsed = time.perf_counter() - start
    return {"transitions": n, "features": basis.size(4), "iterations": 20, "seconds": elapsed}


def time_render(frames: int) -> dict[str, Any]:
    """640x480 frames per second from cart-pole's tracking camera."""
    from tatl_mj import suite

    domain, task = reference()
    env = suite.load(domain, task, task_kwargs={"random": 0})
    env.reset()
    try:
        env.physics.render(480, 640, camera_id="tracking")  # context creation, not timed
        start = time.perf_counter()
        for _ in range(frames):
            env.step(suite.action_set(domain)[1])
            env.physics.render(480, 640, camera_id="tracking")
        elapsed = time.perf_counter() - start
    except Exception as error:  # no GL here: report it, keep the other figures
        return {"skipped": f"rendering failed under MUJOCO_GL={os.environ.get('MUJOCO_GL', '')!r}: {error}"}
    return {"frames": frames, "seconds": elapsed, "fps": frames / elapsed}


def measure_memory(n: int, threads: int) -> dict[str, Any]:
    """Peak traced memory (numpy arrays included) while collecting ``n`` cart-pole transitions.

    ``max_rss_mb`` is the whole process's peak resident size so far (MuJoCo,
    dm_control and the earlier timings included), an upper bound.
    """
    from tatl_mj import sampling

    tracemalloc.start()
    start = time.perf_counter()
    tr = sampling.collect(*reference(), n, seed=0, n_threads=threads)  # the default parallelism
    elapsed = time.perf_counter() - start
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    stored = sum(a.nbytes for a in (tr.states, tr.actions, tr.rewards, tr.next_states, tr.absorbing, tr.last))
    return {
        "transitions": n,
        "stored_mb": stored / 2**20,
        "peak_mb": peak / 2**20,
        "max_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "seconds": elapsed,
    }
