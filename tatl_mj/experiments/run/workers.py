"""Worker lifetime: pool workers die with the process that started them.

A spawned pool worker blocks on a pipe from its parent; if the parent is
killed (kill -9, the out-of-memory killer, a scheduler's SIGTERM) nothing
tells the worker, and it stays, hung, holding its memory. :func:`die_with_parent`
is a pool ``initializer`` with two guards:

- on Linux, ``prctl(PR_SET_PDEATHSIG, SIGKILL)``: the kernel kills the worker
  the moment its parent dies;
- everywhere, a daemon thread that polls ``os.getppid()`` once a second and
  ends the worker when it changes (the parent died and the worker was
  re-parented), for systems without prctl.

PDEATHSIG fires when the *thread* that started the worker ends, so a pool
must live no longer than the thread that submits to it (true of the runner,
which uses it from one function).

Workers also ignore SIGINT: Ctrl-C reaches the whole process group, and only
the main process should decide what an interrupt does (:func:`stop_children`).
The multiprocessing resource tracker exits by itself once the main process
and every worker have closed their end of its pipe.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import multiprocessing
import os
import signal
import sys
import threading
import time

PR_SET_PDEATHSIG = 1  # <linux/prctl.h>
WATCHDOG_PERIOD_S = 1.0


def _set_parent_death_signal() -> bool:
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        return libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _watch(parent: int) -> None:
    while True:
        time.sleep(WATCHDOG_PERIOD_S)
        if os.getppid() != parent:
            os._exit(1)  # no cleanup: the parent that would collect our results is gone


def die_with_parent(parent: int | None = None) -> None:
    """Pool initializer: this process ends within about a second of its parent's death.

    ``parent`` is the parent's pid (default: ``os.getppid()`` now); if the
    parent already died before this ran, the process exits at once.
    """
    parent = os.getppid() if parent is None else parent
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _set_parent_death_signal()
    if os.getppid() != parent:  # the parent died before prctl took effect
        os._exit(1)
    threading.Thread(target=_watch, args=(parent,), name="tatl-parent-watchdog", daemon=True).start()


def stop_children(timeout: float = 2.0) -> int:
    """Ends this process's multiprocessing children (pool workers) now; returns how many.

    SIGTERM first, SIGKILL for any still alive after ``timeout`` seconds. For
    an interrupt: a pool's own shutdown would wait for every running unit.
    """
    children = multiprocessing.active_children()
    for child in children:
        child.terminate()
    for child in children:
        child.join(timeout)
        if child.is_alive():
            child.kill()
            child.join(timeout)
    return len(children)
