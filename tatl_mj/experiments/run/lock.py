"""One run per output folder: an exclusive lock on ``DIR/.lock``.

Two ``tatl run`` into the same folder would both compute every unit and race
on the same records, so the second one refuses at once and names the first.
The lock is an ``fcntl.flock`` on ``DIR/.lock``, which the kernel releases
when its process dies however it dies (kill -9 included): a lock file left by
a dead process is simply taken over. The file holds the holder's pid, host
and command line, only so that the refusal can name it. Where ``fcntl`` does
not exist (Windows), the file is created exclusively and a lock whose pid is
no longer alive on this host is taken over.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import sys
import time
from pathlib import Path
from typing import Iterator

LOCK_NAME = ".lock"

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]


class LockHeld(RuntimeError):
    """Another live process holds the folder's lock; the message names it."""


def _describe(path: Path) -> str:
    try:
        info = json.loads(path.read_text())
        return f"pid {info['pid']} on {info['host']} since {info['since']} ({info['command']})"
    except (OSError, ValueError, KeyError, TypeError):
        return "another process"


def _holder_info() -> bytes:
    info = {
        "pid": os.getpid(),
        "host": socket.gethostname(),
        "since": time.strftime("%Y-%m-%d %H:%M:%S"),
        "command": " ".join(sys.argv) or sys.executable,
    }
    return (json.dumps(info) + "\n").encode()


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, someone else's
        return True
    return True


@contextlib.contextmanager
def hold(root: str | Path) -> Iterator[Path]:
    """Holds the exclusive lock of output folder ``root`` (created if missing) for the block.

    Raises :class:`LockHeld` at once, naming the holder, when another live
    process holds it. Yields the lock file's path.
    """
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    path = root / LOCK_NAME
    if fcntl is None:  # pragma: no cover - Windows
        with _hold_by_pid(path):
            yield path
        return
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)  # not inherited by spawned workers (O_CLOEXEC)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise LockHeld(
                f"{root} is in use by another run: {_describe(path)}; wait for it or use another --out"
            ) from None
        os.ftruncate(fd, 0)
        os.write(fd, _holder_info())
        try:
            yield path
        finally:
            # Emptied, not removed: removing would let a third run lock a new
            # inode while a second still waits on this one.
            os.ftruncate(fd, 0)
    finally:
        os.close(fd)  # releases the flock


@contextlib.contextmanager
def _hold_by_pid(path: Path) -> Iterator[None]:  # pragma: no cover - Windows
    for _ in range(2):
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            break
        except FileExistsError:
            try:
                info = json.loads(path.read_text())
                stale = info["host"] == socket.gethostname() and not _pid_alive(int(info["pid"]))
            except (OSError, ValueError, KeyError, TypeError):
                stale = False
            if not stale:
                raise LockHeld(
                    f"{path.parent} is in use by another run: {_describe(path)}; "
                    f"wait for it, use another --out, or delete {path} if no run is alive"
                ) from None
            path.unlink(missing_ok=True)
    else:
        raise LockHeld(f"{path.parent} is in use by another run: {_describe(path)}")
    try:
        os.write(fd, _holder_info())
        os.close(fd)
        yield
    finally:
        path.unlink(missing_ok=True)
