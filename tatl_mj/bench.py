"""``tatl bench``: how fast tatl-mj collects, learns and renders on this machine.

One process, one measurement after another, for the first task of every domain
with physics (cart-pole, pendulum, mountain car and bicycle today); each
stepping figure is the fastest of ``--repeats`` runs taken in turn with the
others, since a shared machine's speed drifts by up to 2x within seconds:

- ``dm_control``: a Python loop over the environment's ``step`` with random
  actions (resetting at episode ends), the way a hand-written collector works,
  also given as simulated seconds per wall-clock second (``real_time_factor``);
- ``dm_control_floor``: the same loop over the same physics with a task that
  does nothing: dm_control's own cost per step, the most any dm_control loop of
  this physics can reach here;
- ``sampler``: :func:`tatl_mj.sampling.collect`, whole random episodes in
  lockstep on ``--threads`` MuJoCo threads, task logic included;
- ``rollout``: raw ``mujoco.rollout`` of the bare model, open loop, no task
  logic and no episode ends: the physical limit here;
- ``gymnasium``: the peer a user would otherwise pick, Gymnasium's own Python
  loop (``gymnasium.make``, random actions, reset at episode ends) for
  CartPole-v1, Pendulum-v1 and MountainCar-v0; skipped with a note when
  gymnasium is not installed.

Then the Gymnasium vector envs of every physics task of those domains
(``--vector-tasks``), ``--vector-envs`` (64) copies stepped with random actions
(env-steps per second, autoreset included): ``vector``, the native one
(``gym.make_vec(..., vectorization_mode="vector_entry_point")``, on ``--threads``
MuJoCo threads), beside ``sync_vector`` (Gymnasium's ``SyncVectorEnv`` over the
same id) and ``rollout`` (raw ``mujoco.rollout`` of the same task, as above).

Then Fitted Q-Iteration on 100 000 cart-pole transitions, 640x480 frames per
second from the tracking camera (under the current ``MUJOCO_GL``), and the peak
memory of collecting 10^6 cart-pole transitions. ``--json`` prints one JSON
object per line; the last one is the summary.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import platform
import resource
import time
import tracemalloc
from collections.abc import Callable
from typing import Any

import numpy as np


def _physics_tasks() -> dict[str, str]:
    """The first task of every domain with physics: what ``tatl bench`` times, by domain."""
    from tatl_mj import suite

    out: dict[str, str] = {}
    for domain, task in suite.ALL_TASKS:
        if domain not in out and not suite.describe(domain, task).discrete:
            out[domain] = task
    return out


def _reference() -> tuple[str, str]:
    """The task of the FQI, memory and render figures: the first physics task (cart-pole's)."""
    return next(iter(_physics_tasks().items()))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``tatl bench``."""
    parser.add_argument("--json", action="store_true", help="one JSON object per line, the summary last")
    parser.add_argument(
        "--domains",
        default=None,
        help="comma-separated subset of the suite's physics domains (default: all of them)",
    )
    parser.add_argument("--threads", type=int, default=2, help="MuJoCo threads for sampler and rollout (default 2)")
    parser.add_argument("--seconds", type=float, default=2.0, help="target length of each timing (default 2 s)")
    parser.add_argument(
        "--repeats",
        type=int,
        default=3,
        help="times each stepping figure is taken, in turn with the others; the fastest is kept (default 3)",
    )
    parser.add_argument(
        "--memory-transitions",
        type=int,
        default=1_000_000,
        help="cart-pole transitions collected for the memory figure (default 10^6; 0 skips it)",
    )
    parser.add_argument(
        "--fqi-transitions",
        type=int,
        default=100_000,
        help="cart-pole transitions FQI is fitted on (default 100 000; 0 skips it)",
    )
    parser.add_argument("--render-frames", type=int, default=60, help="frames for the render figure (0 skips it)")
    parser.add_argument(
        "--vector-tasks",
        default=None,
        help="comma-separated domain/task list for the vector-env figures (default: every physics task of "
        "the domains timed; empty skips them)",
    )
    parser.add_argument("--vector-envs", type=int, default=64, help="envs of each vector env (default 64)")


def _vector_tasks(args: argparse.Namespace, domains: list[str]) -> list[tuple[str, str]]:
    """The ``domain/task`` pairs whose vector envs are timed (checked against the physics tasks)."""
    from tatl_mj import suite

    physics = [(d, t) for d, t in suite.ALL_TASKS if not suite.describe(d, t).discrete]
    if args.vector_tasks is None:
        return [(d, t) for d, t in physics if d in domains]
    chosen = [tuple(item.split("/", 1)) for item in str(args.vector_tasks).split(",") if item]
    unknown = [f"{c[0]}/{c[-1]}" for c in chosen if c not in physics]
    if unknown:
        raise ValueError(f"--vector-tasks: unknown {unknown}; valid: {[f'{d}/{t}' for d, t in physics]}")
    return chosen  # type: ignore[return-value]


def _check(args: argparse.Namespace) -> list[str]:
    physics = _physics_tasks()
    domains = list(physics) if args.domains is None else [d for d in str(args.domains).split(",") if d]
    unknown = sorted(set(domains) - set(physics))
    if not domains:
        raise ValueError(f"--domains: none given; valid: {sorted(physics)}")
    if unknown:
        raise ValueError(f"--domains: unknown {unknown}; valid: {sorted(physics)}")
    if args.threads < 1:
        raise ValueError(f"--threads must be >= 1, got {args.threads}")
    if args.repeats < 1:
        raise ValueError(f"--repeats must be >= 1, got {args.repeats}")
    if args.vector_envs < 1:
        raise ValueError(f"--vector-envs must be >= 1, got {args.vector_envs}")
    if not args.seconds > 0:
        raise ValueError(f"--seconds must be > 0, got {args.seconds}")
    for name in ("memory_transitions", "fqi_transitions", "render_frames"):
        if getattr(args, name) < 0:
            raise ValueError(f"--{name.replace('_', '-')} must be >= 0, got {getattr(args, name)}")
    return domains


def machine() -> dict[str, Any]:
    """CPU model, cores, and the versions that decide the figures."""
    from importlib import metadata

    import mujoco

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    usable = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "usable_cores": usable,
        "load_average_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
        "python": platform.python_version(),
        "mujoco": mujoco.__version__,
        "dm_control": metadata.version("dm-control"),
        "numpy": np.__version__,
        "mujoco_gl": os.environ.get("MUJOCO_GL", ""),
    }


# --- Stepping -------------------------------------------------------------------------


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


def time_vector_env(
    domain: str, task: str, seconds: float, threads: int, num_envs: int, mode: str, seed: int = 0
) -> dict[str, Any]:
    """Random actions through a Gymnasium vector env of ``num_envs`` copies of the task's id.

    ``mode`` is ``make_vec``'s ``vectorization_mode``: ``"vector_entry_point"``
    (tatl-mj's batched one, on ``threads`` MuJoCo threads) or ``"sync"``
    (``SyncVectorEnv``). Counts env-steps; autoreset (``NEXT_STEP``) included.
    Returns ``{"skipped": why}`` when gymnasium is not installed.
    """
    try:
        import gymnasium

        from tatl_mj import gym as tatl_gym
    except ImportError as error:
        return {"skipped": f"gymnasium is not installed ({error})"}
    options = {"n_threads": threads} if mode == "vector_entry_point" else {}
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
            return {"steps": steps, "seconds": elapsed, "steps_per_s": steps / elapsed, "num_envs": num_envs}


# --- Learning, rendering, memory ----------------------------------------------------------


def time_fqi(n: int, threads: int) -> dict[str, Any]:
    """Linear-RBF FQI (20 iterations) on ``n`` random cart-pole transitions."""
    from tatl_mj import sampling

    try:
        from tatl_mj.transfer import features, fqi
    except ImportError as error:
        return {"skipped": f"tatl_mj.transfer.fqi is not available: {error}"}
    tr = sampling.collect(*_reference(), n, seed=0, n_threads=threads)
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

    domain, task = _reference()
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
    tr = sampling.collect(*_reference(), n, seed=0, n_threads=threads)  # the default parallelism
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


# --- The command ----------------------------------------------------------------------------


def run(args: argparse.Namespace) -> int:
    """Runs the benchmark; prints a table, or JSON lines with ``--json``. Returns 0."""
    try:
        domains = _check(args)
        _vector_tasks(args, domains)
    except ValueError as error:
        print(f"tatl bench: {error}")
        return 2
    emit = (lambda record: print(json.dumps(record), flush=True)) if args.json else _print_record
    info = machine()
    if not args.json:
        print(
            f"machine: {info['cpu']}, {info['cores']} cores ({info['usable_cores']} usable), "
            f"load {info['load_average_1min']}, mujoco {info['mujoco']}, threads {args.threads}"
        )
    physics = _physics_tasks()
    per_domain = {domain: _time_domain(domain, physics[domain], args, emit) for domain in domains}
    vector = {f"{d}/{t}": _time_vector(d, t, args, emit) for d, t in _vector_tasks(args, domains)}
    extra: dict[str, Any] = {}
    # Memory first, so that the process's peak RSS is not FQI's or the renderer's.
    if args.memory_transitions:
        extra["memory"] = measure_memory(args.memory_transitions, args.threads)
        emit({"kind": "memory", **extra["memory"]})
    if args.fqi_transitions:
        extra["fqi"] = time_fqi(args.fqi_transitions, args.threads)
        emit({"kind": "fqi", **extra["fqi"]})
    if args.render_frames:
        extra["render"] = time_render(args.render_frames)
        emit({"kind": "render", **extra["render"]})
    summary: dict[str, Any] = {
        "kind": "summary",
        "threads": args.threads,
        "vector_envs": args.vector_envs,
        "machine": info,
    }
    if _reference()[0] in per_domain:
        summary.update(per_domain[_reference()[0]])
    summary["domains"] = per_domain
    summary["vector"] = {task: figures for task, figures in vector.items() if figures}
    summary["fqi_fit_s"] = extra.get("fqi", {}).get("seconds")
    summary["render_fps"] = extra.get("render", {}).get("fps")
    summary["memory_peak_mb"] = extra.get("memory", {}).get("peak_mb")
    emit(summary)
    return 0


def _time_domain(domain: str, task: str, args: argparse.Namespace, emit: Callable[[dict], None]) -> dict[str, float]:
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
    figures = _fastest_of(timers, args.repeats)
    for path, record in figures.items():
        emit({"kind": "steps", "domain": domain, "task": task, "path": path, **record})
    return {f"{p}_steps_per_s": r["steps_per_s"] for p, r in figures.items()} | _ratios(figures)


def _time_vector(domain: str, task: str, args: argparse.Namespace, emit: Callable[[dict], None]) -> dict[str, float]:
    """Times one task's native vector env beside SyncVectorEnv and raw rollout; returns rates and ratios
    (empty, with a note emitted, without gymnasium)."""
    from tatl_mj import sampling

    timed = functools.partial(time_vector_env, domain, task, args.seconds / 2, args.threads, args.vector_envs)
    probe = time_vector_env(domain, task, 0.0, args.threads, 1, "sync")  # is gymnasium there at all?
    if "skipped" in probe:
        emit({"kind": "vector", "domain": domain, "task": task, **probe})
        return {}
    timers = {
        "vector": functools.partial(timed, "vector_entry_point"),
        "sync_vector": functools.partial(timed, "sync"),
        "rollout": functools.partial(sampling.time_rollout, domain, task, args.seconds / 2, args.threads),
    }
    figures = _fastest_of(timers, args.repeats)
    for path, record in figures.items():
        emit({"kind": "vector", "domain": domain, "task": task, "path": path, **record})
    rate = {path: record["steps_per_s"] for path, record in figures.items()}
    return {f"{p}_steps_per_s": r for p, r in rate.items()} | {
        "vector_vs_rollout": rate["vector"] / rate["rollout"],
        "vector_vs_rollout_paired": _paired(figures, "vector", "rollout"),
        "vector_vs_sync_vector": rate["vector"] / rate["sync_vector"],
        "vector_vs_sync_vector_paired": _paired(figures, "vector", "sync_vector"),
        # The most any vector env of this physics could reach against SyncVectorEnv here.
        "rollout_vs_sync_vector": rate["rollout"] / rate["sync_vector"],
    }


def _paired(figures: dict[str, dict[str, Any]], path: str, against: str) -> float:
    """The median over repeats of ``path``'s rate over ``against``'s timed right beside it: the
    machine's drift between repeats cancels."""
    return float(np.median(np.divide(figures[path]["each_steps_per_s"], figures[against]["each_steps_per_s"])))


def _ratios(figures: dict[str, dict[str, Any]]) -> dict[str, float]:
    """How the stepping paths' fastest rates compare."""
    rate = {path: record["steps_per_s"] for path, record in figures.items()}
    ratios = {
        "sampler_vs_dm_control": rate["sampler"] / rate["dm_control"],
        "sampler_vs_rollout": rate["sampler"] / rate["rollout"],
        # Each repeat's sampler against the rollout timed right after it: the machine's
        # drift between repeats cancels; the median of those pairs.
        "sampler_vs_rollout_paired": _paired(figures, "sampler", "rollout"),
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


def _fastest_of(timers: dict[str, Any], repeats: int) -> dict[str, dict[str, Any]]:
    """Each timer's fastest of ``repeats`` runs, the timers taken in turn.

    Other tenants slow a shared machine by up to 2x for seconds at a time; taking
    the paths in turn and keeping each one's best lets them see the same
    machine. Each record notes the slowest rate too (``slowest_steps_per_s``).
    """
    runs: dict[str, list[dict[str, Any]]] = {path: [] for path in timers}
    for _ in range(repeats):
        for path, timer in timers.items():
            runs[path].append(timer())
    figures = {}
    for path, records in runs.items():
        best = max(records, key=lambda r: r["steps_per_s"])
        figures[path] = {
            **best,
            "repeats": repeats,
            "slowest_steps_per_s": min(r["steps_per_s"] for r in records),
            "each_steps_per_s": [r["steps_per_s"] for r in records],  # in the order taken
        }
    return figures


def _print_record(record: dict[str, Any]) -> None:
    kind = record["kind"]
    if kind in ("steps", "vector") and "skipped" not in record:
        where = record["domain"] if kind == "steps" else f"{record['domain']}/{record['task']}"
        real_time = f", {record['real_time_factor']:.0f}x real time" if "real_time_factor" in record else ""
        peer = f", {record['env_id']}" if "env_id" in record else ""
        spread = (
            f", slowest of {record['repeats']}: {record['slowest_steps_per_s']:,.0f}"
            if record.get("repeats", 1) > 1
            else ""
        )
        print(
            f"{where:>13} {record['path']:>16}: {record['steps_per_s']:>11,.0f} steps/s "
            f"({record['steps']} steps in {record['seconds']:.2f} s{real_time}{peer}{spread})"
        )
    elif "skipped" in record:
        where = f" for {record['domain']}" if "domain" in record else ""
        where += f"/{record['task']}" if "task" in record else ""
        print(f"{kind}{where}: skipped ({record['skipped']})")
    elif kind == "fqi":
        print(
            f"FQI: {record['transitions']} transitions, {record['features']} RBF features, "
            f"{record['iterations']} iterations in {record['seconds']:.2f} s"
        )
    elif kind == "render":
        print(f"render: {record['fps']:.1f} frames/s at 640x480")
    elif kind == "memory":
        print(
            f"memory: {record['transitions']} cart-pole transitions stored in {record['stored_mb']:.1f} MB; "
            f"peak {record['peak_mb']:.1f} MB while collecting ({record['seconds']:.1f} s), "
            f"process max RSS so far {record['max_rss_mb']:.0f} MB"
        )
    elif kind == "summary":
        for domain, figures in record["domains"].items():
            peer = (
                f", {figures['sampler_vs_gymnasium']:.2f}x Gymnasium's loop"
                f" (raw rollout itself: {figures['rollout_vs_gymnasium']:.2f}x)"
                if "sampler_vs_gymnasium" in figures
                else ""
            )
            print(
                f"{domain:>13}: sampler {figures['sampler_vs_dm_control']:.1f}x dm_control, "
                f"{figures['sampler_vs_rollout']:.2f}x raw rollout"
                f" (median of each repeat's pair {figures['sampler_vs_rollout_paired']:.2f}){peer}; "
                f"raw rollout {figures['rollout_vs_dm_control']:.1f}x dm_control; "
                f"dm_control loop {figures['dm_control_vs_floor']:.2f}x dm_control's own floor"
            )
        for task, figures in record["vector"].items():
            print(
                f"{task}: native vector env ({record['vector_envs']} envs) "
                f"{figures['vector_vs_rollout']:.2f}x raw rollout (median of each repeat's pair "
                f"{figures['vector_vs_rollout_paired']:.2f}), {figures['vector_vs_sync_vector']:.1f}x SyncVectorEnv "
                f"(paired {figures['vector_vs_sync_vector_paired']:.1f}; raw rollout itself "
                f"{figures['rollout_vs_sync_vector']:.1f}x)"
            )
