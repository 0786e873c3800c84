"""The Gymnasium vector envs: the native one beside SyncVectorEnv and raw ``mujoco.rollout``."""

from __future__ import annotations

import argparse
import functools
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from tatl_mj.bench.contexts import contexts_for, time_rollout_contexts
from tatl_mj.bench.timing import fastest_of, paired


def time_vector_env(
    domain: str,
    task: str,
    seconds: float,
    threads: int,
    num_envs: int,
    mode: str,
    seed: int = 0,
    contexts: str | None = None,
) -> dict[str, Any]:
    """Random actions through a Gymnasium vector env of ``num_envs`` copies of the task's id.

    ``mode`` is ``make_vec``'s ``vectorization_mode``: ``"vector_entry_point"``
    (tatl-mj's batched one, on ``threads`` MuJoCo threads) or ``"sync"``
    (``SyncVectorEnv``). Counts env-steps; autoreset (``NEXT_STEP``) included.
    ``contexts``: a context per env, ``"distinct"`` or ``"resample"``d at each
    reset (:mod:`tatl_mj.bench.contexts`; the native env only).
    Returns ``{"skipped": why}`` when gymnasium is not installed.
    """
    try:
        import gymnasium

        from tatl_mj import gym as tatl_gym
    except ImportError as error:
        return {"skipped": f"gymnasium is not installed ({error})"}
    options: dict[str, Any] = {"n_threads": threads} if mode == "vector_entry_point" else {}
    if contexts is not None:
        options["contexts"] = contexts_for(domain, task, contexts, num_envs, seed)
    envs = gymnasium.make_vec(tatl_gym.gym_id(domain, task), num_envs=num_envs, vectorization_mode=mode, **options)
    space = envs.single_action_space
    rng = np.random.default_rng(seed)
    envs.reset(seed=seed)
    steps, start = 0, time.perf_counter()
    while True:
        for action in rng.uniform(space.low, space.high, size=(100, num_envs, *space.shape)).astype(space.dtype):
            envs.step(action)
        steps += 100 * num_envs
        elapsed = time.perf_counter() - start
        if elapsed >= seconds:
            envs.close()
            record = {"steps": steps, "seconds": elapsed, "steps_per_s": steps / elapsed, "num_envs": num_envs}
            return record | ({} if contexts is None else {"contexts": contexts})


def time_vector(domain: str, task: str, args: argparse.Namespace, emit: Callable[[dict], None]) -> dict[str, float]:
    """Times one task's native vector env beside SyncVectorEnv and raw rollout; returns rates and ratios
    (empty, with a note emitted, without gymnasium)."""
    from tatl_mj import sampling

    timed = functools.partial(time_vector_env, domain, task, args.seconds / 2, args.threads, args.vector_envs)
    probe = time_vector_env(domain, task, 0.0, args.threads, 1, "sync")  # is gymnasium there at all?
    if "skipped" in probe:
        emit({"kind": "vector", "domain": domain, "task": task, **probe})
        return {}
    if args.contexts is not None:  # raw rollout over the same per-env models; no SyncVectorEnv
        timers = {
            "vector": functools.partial(timed, "vector_entry_point", contexts=args.contexts),
            "rollout": functools.partial(
                time_rollout_contexts, domain, task, args.seconds / 2, args.threads, args.vector_envs, args.contexts
            ),
        }
    else:
        timers = {
            "vector": functools.partial(timed, "vector_entry_point"),
            "sync_vector": functools.partial(timed, "sync"),
            "rollout": functools.partial(sampling.time_rollout, domain, task, args.seconds / 2, args.threads),
        }
    figures = fastest_of(timers, args.repeats)
    for path, record in figures.items():
        emit({"kind": "vector", "domain": domain, "task": task, "path": path, **record})
    rate = {path: record["steps_per_s"] for path, record in figures.items()}
    ratios = {
        "vector_vs_rollout": rate["vector"] / rate["rollout"],
        "vector_vs_rollout_paired": paired(figures, "vector", "rollout"),
    }
    if args.contexts is not None:
        return {f"{p}_steps_per_s": r for p, r in rate.items()} | ratios | {"contexts": args.contexts}
    return (
        {f"{p}_steps_per_s": r for p, r in rate.items()}
        | ratios
        | {
            "vector_vs_sync_vector": rate["vector"] / rate["sync_vector"],
            "vector_vs_sync_vector_paired": paired(figures, "vector", "sync_vector"),
            # The most any vector env of this physics could reach against SyncVectorEnv here.
            "rollout_vs_sync_vector": rate["rollout"] / rate["sync_vector"],
        }
    )
