"""Where work units run: a local process pool, or a Ray cluster (``tatl run --executor``).

A dispatcher takes the first jobs and a callback (``Then``) that records each finished
unit's result and returns the jobs it unlocked (a source's methods), and runs until none
is left. Both run :func:`tatl_mj.experiments.run.runner.work` in their workers, one thread a
unit, so a record does not depend on the executor.
"""

from __future__ import annotations

import collections
import os
import traceback
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any, Callable

from tatl_mj.experiments.run import reaper
from tatl_mj.experiments.run import workers as workers_mod

EXECUTORS = ("local", "ray")
CONNECT_TIMEOUT_S = 10.0

Job = tuple[Any, tuple]
"""A unit and the arguments its worker function takes."""

Then = Callable[[Any, dict], list[Job]]
"""What a dispatcher calls with each finished unit's result: it records the result
and returns the jobs that unit has unlocked (a source's methods), to run next."""

Work = Callable[..., dict]
"""The worker function: never raises, a failure is returned as ``{"error": traceback}``."""


class ExecutorError(RuntimeError):
    """The executor cannot start: e.g. no Ray cluster answers at ``address`` (raised before any work)."""


def dispatcher(executor: str, workers: int, address: str | None) -> Callable[[Work, list[Job], Then], None]:
    """The dispatch function of ``executor``; a Ray ``address`` is checked now, before any work."""
    if executor not in EXECUTORS:
        raise ValueError(f"unknown executor {executor!r}; valid executors: {list(EXECUTORS)}")
    if executor == "ray" and address:
        check_address(address)  # before the run touches its folder
    if executor == "ray":
        return lambda work, jobs, then: _ray(work, jobs, workers, address, then)
    return lambda work, jobs, then: _local(work, jobs, workers, then)


def _local(work: Work, jobs: list[Job], workers: int, then: Then) -> None:
    if workers <= 1:
        queue = collections.deque(jobs)
        while queue:
            unit, args = queue.popleft()
            queue.extend(then(unit, work(*args)))
        return
    import multiprocessing

    # spawn: MuJoCo/GL state must not be forked into workers.
    # [robustness] workers die with this process, however it dies.
    # One pool for sources and methods: a method starts as soon as its source is done.
    with ProcessPoolExecutor(
        max_workers=workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=workers_mod.die_with_parent,
        initargs=(os.getpid(),),
    ) as pool:
        futures = {pool.submit(work, *args): unit for unit, args in jobs}
        while futures:
            done, _ = wait(futures, return_when=FIRST_COMPLETED)
            for future in done:
                unit = futures.pop(future)
                try:
                    result = future.result()
                except Exception:  # noqa: BLE001 - e.g. a worker killed by the OS
                    result = {"error": traceback.format_exc()}
                for next_unit, args in then(unit, result):
                    futures[pool.submit(work, *args)] = next_unit


def check_address(address: str) -> None:
    """Raises ExecutorError unless something accepts connections at a Ray ``address``.

    ``ray.init`` retries an address where nothing listens for minutes (measured with
    Ray 2.60); one TCP connection here, to the address given and nowhere else, says
    at once. ``auto`` and ``local`` are left to Ray.
    """
    import socket

    if address in ("auto", "local"):
        return
    where = address.split("://", 1)[-1]  # ray://host:port (Ray Client) or host:port
    host, _, port = where.rpartition(":")
    if not host or not port.isdigit():
        raise ExecutorError(
            f"--address {address!r}: expected host:port (e.g. 127.0.0.1:6379), 'auto' or ray://host:port"
        )
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as error:
        raise ExecutorError(
            f"no Ray cluster answers at --address {address} ({error.strerror or error}); "
            "start one there (ray start --head --port PORT) or give its address"
        ) from None


def _ray(work: Work, jobs: list[Job], workers: int, address: str | None, then: Then) -> None:
    try:
        import ray
    except ImportError:
        raise ExecutorError(
            "--executor ray needs Ray: pip install 'tatl-mj[ray]' (or pip install 'ray>=2.9,<3')"
        ) from None
    started = not ray.is_initialized()
    # [robustness] a local instance's agents would outlive a killed run by 20-30 s.
    watcher = reaper.start() if started and not address else None
    if started:
        kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False}
        if address:
            kwargs["address"] = address
        else:
            kwargs["num_cpus"] = max(workers, 1)
        try:
            ray.init(**kwargs)
        except Exception as error:  # noqa: BLE001 - Ray raises several kinds (ConnectionError, RuntimeError)
            ray.shutdown()
            if watcher is not None:
                watcher.terminate()
                watcher.wait()
            first = (str(error).strip().splitlines() or [type(error).__name__])[0]
            where = f"at {address}" if address else "(a local instance)"
            raise ExecutorError(f"cannot start Ray {where}: {first}") from None
    try:
        remote = ray.remote(num_cpus=1)(work)
        refs = {remote.remote(*args): unit for unit, args in jobs}
        while refs:
            done, _ = ray.wait(list(refs), num_returns=1)
            for ref in done:
                unit = refs.pop(ref)
                try:
                    result = ray.get(ref)
                except Exception:  # noqa: BLE001 - a lost node or worker
                    result = {"error": traceback.format_exc()}
                for next_unit, args in then(unit, result):
                    refs[remote.remote(*args)] = next_unit
    finally:
        if started:
            ray.shutdown()
        if watcher is not None:
            watcher.terminate()
            watcher.wait()


__all__ = ["EXECUTORS", "ExecutorError", "Job", "Then", "check_address", "dispatcher"]
