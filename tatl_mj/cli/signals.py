"""Stopping a run or a comparison on SIGINT or SIGTERM: workers stopped, the exit status and its line."""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator


class Interrupted(BaseException):
    """SIGINT or SIGTERM arrived during a run (a BaseException, as KeyboardInterrupt is)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def _interrupt(signum: int, frame: object) -> None:
    from tatl_mj.experiments.run import workers

    # Stop the workers first: a pool's shutdown would otherwise wait for every running unit.
    workers.stop_children()
    raise Interrupted(signum)


@contextlib.contextmanager
def stop_signals() -> Iterator[None]:
    """SIGINT and SIGTERM stop the workers and raise :class:`Interrupted` within the block."""
    import signal

    previous = {sig: signal.signal(sig, _interrupt) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def stopped(command: str, stop: Interrupted, out: str) -> int:
    """Says a stopped command's finished units are kept; its exit status, 128 + the signal."""
    import signal

    name = signal.Signals(stop.signum).name
    # Leading newline: the progress bar's line is left unfinished.
    print(
        f"\ntatl {command}: stopped by {name}; finished units are kept in {out}, run the same command to resume",
        file=sys.stderr,
    )
    return 128 + stop.signum
