"""A reaper for processes that do not die with the run: a local Ray instance's.

Pool workers die with the run by themselves (``workers.die_with_parent``). A
local Ray instance started by ``ray.init`` does not: when the driver is killed
(kill -9, the out-of-memory killer), the GCS, raylet and workers go within
about two seconds, but Ray's dashboard and runtime-env agents linger for 20-30 s
(they try to report the raylet's death to a GCS that is already gone), measured
with Ray 2.60 here.

:func:`start` launches a small separate process that every ``PERIOD_S`` seconds
notes the run's descendants (pid and start time, so a reused pid is never
hit); once the run's process is gone, however it died, it sends SIGKILL to every
noted process still alive and exits. Linux only (it reads ``/proc``); elsewhere
:func:`start` returns None and Ray's own clean-up is all there is. Processes of
a cluster the run only connected to (``--address``) are not descendants and are
never touched.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

PERIOD_S = 0.25


def _stat(pid: int) -> tuple[int, int] | None:
    """(parent pid, start time in clock ticks) of a live process, None when gone or a zombie."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text.rsplit(")", 1)[1].split()
    if fields[0] in ("Z", "X"):
        return None
    return int(fields[1]), int(fields[19])


def _descendants(root: int, skip: int) -> dict[int, int]:
    """{pid: start time} of every live descendant of ``root`` except ``skip``."""
    parents: dict[int, tuple[int, int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit() and (stat := _stat(int(entry.name))):
            parents[int(entry.name)] = stat
    found: dict[int, int] = {}
    frontier = {root}
    while frontier:
        frontier = {pid for pid, (ppid, _) in parents.items() if ppid in frontier and pid not in found}
        found.update({pid: parents[pid][1] for pid in frontier})
    found.pop(skip, None)
    return found


def watch(run_pid: int, run_start: int) -> int:
    """Note ``run_pid``'s descendants until it ends, then SIGKILL the survivors; how many."""
    noted: dict[int, int] = {}
    me = os.getpid()
    while (stat := _stat(run_pid)) is not None and stat[1] == run_start:
        noted.update(_descendants(run_pid, me))
        time.sleep(PERIOD_S)
    killed = 0
    for pid, start in noted.items():
        now = _stat(pid)
        if now is not None and now[1] == start:
            try:
                os.kill(pid, signal.SIGKILL)
                killed += 1
            except ProcessLookupError:
                pass
    return killed


def start() -> subprocess.Popen | None:
    """Start a reaper for this process (see the module docstring); None off Linux."""
    me = os.getpid()
    stat = _stat(me) if sys.platform.startswith("linux") else None
    if stat is None:
        return None
    return subprocess.Popen(
        [sys.executable, "-m", "tatl_mj.experiments.run.reaper", str(me), str(stat[1])],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,  # Ctrl-C to the run's process group must not end it first
        close_fds=True,
    )


if __name__ == "__main__":
    watch(int(sys.argv[1]), int(sys.argv[2]))
