"""Stepping the first task of each physics domain: dm_control's loop, its floor, the sampler,
raw rollout and Gymnasium's own loop."""

from __future__ import annotations

import argparse
import functools
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from tatl_mj.bench.timing import fastest_of, paired


def time_dm_control(domain: str, task: str, seconds: float, seed: int = 0) -> dict[str, Any]:
    """Random actions through ``env.step``, resetting at episode ends."""
    from tatl_mj import suite

    env = suite.load(domain, task, task_kwargs={"random": seed})
    actions = suite.action_set(domain)
    rng = np.random.default_rng(seed)
    env.reset()
    steps, start = 0, time.perf_counter()
    while True:
        for a in rng.integers(len(actions), size=100):
            if env.step(actions[a]).last():
                env.reset()
        steps += 100
        elapsed = time.perf_counter() - start
        if elapsed >= seconds:
            return {
                "steps": steps,
                "seconds": elapsed,
                "steps_per_s": steps / elapsed,
                # simulated seconds per wall-clock second
                "real_time_factor": steps * env.control_timestep() / elapsed,
            }


def time_dm_control_floor(domain: str, task: str, seconds: float, seed: int = 0) -> dict[str, Any]:
    """dm_control's own cost per step: ``control.Environment`` over the same physics, bare task.

    The task does no work (a constant observation, zero reward, full control
    vectors set as given; episodes start where the domain's start), so this is
    the fastest any dm_control task's loop over this physics can go here.
    """
    import collections

    from dm_control.rl import control
    from dm_control.suite import base

    from tatl_mj import suite

    env = suite.load(domain, task, task_kwargs={"random": seed})
    domain_task = env.task
    observation = collections.OrderedDict(state=np.zeros(1))

    class Bare(base.Task):
        def initialize_episode(self, physics: Any) -> None:
            qpos, qvel = domain_task.start_configurations(physics, 1)
            physics.data.qpos[:], physics.data.qvel[:] = qpos[0], qvel[0]

        def get_observation(self, physics: Any) -> collections.OrderedDict:
            return observation

        def get_reward(self, physics: Any) -> float:
            return 0.0

    bare = control.Environment(env.physics, Bare(random=seed), control_timestep=env.control_timestep())
    controls = domain_task.controls(np.asarray(suite.action_set(domain), np.float64), domain_task.random)
    rng = np.random.default_rng(seed)
    steps, start = 0, time.perf_counter()
    while True:
        bare.reset()  # every 100 steps, about as often as random episodes end
        for a in rng.integers(len(controls), size=100):
            bare.step(controls[a])
        steps += 100
        elapsed = time.perf_counter() - start
        if elapsed >= seconds:
            return {"steps": steps, "seconds": elapsed, "steps_per_s": steps / elapsed}


def time_sampler(domain: str, task: str, seconds: float, threads: int, seed: int = 0) -> dict[str, Any]:
    """:func:`sampling.collect` of random episodes, sized from a short pilot run."""
    from tatl_mj import sampling

    pilot_n = 2000
    start = time.perf_counter()
    sampling.collect(domain, task, pilot_n, seed=seed, n_threads=threads)  # also builds the cache
    rate = pilot_n / (time.perf_counter() - start)
    n = max(pilot_n, int(rate * seconds))
    start = time.perf_counter()
    tr = sampling.collect(domain, task, n, seed=seed + 1, n_threads=threads)
    elapsed = time.perf_counter() - start
    return {
        "steps": n,
        "seconds": elapsed,
        "steps_per_s": n / elapsed,
        "episodes": int(tr.last.sum()),
        "batched": sampling.is_batched(domain, task),
    }


def time_gymnasium(env_id: str, seconds: float, seed: int = 0) -> dict[str, Any]:
    """Gymnasium's own loop: ``env.step`` with random actions, resetting at episode ends.

    Returns ``{"skipped": why}`` when gymnasium is not installed.
    """
    try:
        import gymnasium
    except ImportError as error:
        return {"skipped": f"gymnasium is not installed ({error})"}
    env = gymnasium.make(env_id)
    space = env.action_space
    rng = np.random.default_rng(seed)

    def draw() -> Any:
        if isinstance(space, gymnasium.spaces.Discrete):
            return rng.integers(space.n, size=100)
        return rng.uniform(space.low, space.high, size=(100, *space.shape)).astype(space.dtype)

    env.reset(seed=seed)
    steps, start = 0, time.perf_counter()
    while True:
        for action in draw():
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
        steps += 100
        elapsed = time.perf_counter() - start
        if elapsed >= seconds:
            env.close()
            return {
                "env_id": env_id,
                "steps": steps,
                "seconds": elapsed,
                "steps_per_s": steps / elapsed,
                "gymnasium": gymnasium.__version__,
            }


def time_domain(domain: str, task: str, args: argparse.Namespace, emit: Callable[[dict], None]) -> dict[str, float]:
    """Times every stepping path of one domain's task (emitting each figure); returns its rates and ratios."""
    from tatl_mj import sampling, suite

    timers: dict[str, Any] = {
        "dm_control": functools.partial(time_dm_control, domain, task, args.seconds / 2),
        "dm_control_floor": functools.partial(time_dm_control_floor, domain, task, args.seconds / 2),
        "sampler": functools.partial(time_sampler, domain, task, args.seconds, args.threads),
        "rollout": functools.partial(sampling.time_rollout, domain, task, args.seconds / 2, args.threads),
    }
    peer_id = suite.describe(domain, task).gymnasium_peer
    if peer_id is not None:
        peer = time_gymnasium(peer_id, 0.0)  # 100 steps: is it there at all?
        if "skipped" in peer:
            emit({"kind": "gymnasium", "domain": domain, **peer})
        else:
            timers["gymnasium"] = functools.partial(time_gymnasium, peer_id, args.seconds / 2)
    figures = fastest_of(timers, args.repeats)
    for path, record in figures.items():
        emit({"kind": "steps", "domain": domain, "task": task, "path": path, **record})
    return {f"{p}_steps_per_s": r["steps_per_s"] for p, r in figures.items()} | ratios(figures)


def ratios(figures: dict[str, dict[str, Any]]) -> dict[str, float]:
    """How the stepping paths' fastest rates compare."""
    rate = {path: record["steps_per_s"] for path, record in figures.items()}
    ratios = {
        "sampler_vs_dm_control": rate["sampler"] / rate["dm_control"],
        "sampler_vs_rollout": rate["sampler"] / rate["rollout"],
        # Each repeat's sampler against the rollout timed right after it: the machine's
        # drift between repeats cancels; the median of those pairs.
        "sampler_vs_rollout_paired": paired(figures, "sampler", "rollout"),
        # The most any sampler of the same physics could gain over the loop here.
        "rollout_vs_dm_control": rate["rollout"] / rate["dm_control"],
        # What the task's own logic leaves of dm_control's loop over this physics.
        "dm_control_vs_floor": rate["dm_control"] / rate["dm_control_floor"],
    }
    if "gymnasium" in figures:
        ratios["sampler_vs_gymnasium"] = rate["sampler"] / rate["gymnasium"]
        # The most any MuJoCo sampler of this physics could reach against Gymnasium.
        ratios["rollout_vs_gymnasium"] = rate["rollout"] / rate["gymnasium"]
    return ratios
