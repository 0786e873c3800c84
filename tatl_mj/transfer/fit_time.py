"""The seconds this process has spent fitting FQI: a cost meter the runner reads.

With the physics, FQI's fits are the part of a run's work that code keeping every
fit cannot save, so a run reports both (``fqi_s`` in the records). The meter is
process-global on purpose: a unit's worker reads it before and after the unit.
"""

from __future__ import annotations

import functools
import time
from typing import Callable, ParamSpec, TypeVar

_P = ParamSpec("_P")
_R = TypeVar("_R")

_SECONDS = [0.0]


def fqi_seconds() -> float:
    """Seconds this process has spent in functions wrapped by :func:`timed` so far."""
    return _SECONDS[0]


def timed(fit: Callable[_P, _R]) -> Callable[_P, _R]:
    """``fit``, its seconds added to :func:`fqi_seconds`."""

    @functools.wraps(fit)
    def timed_fit(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        start = time.perf_counter()
        try:
            return fit(*args, **kwargs)
        finally:
            _SECONDS[0] += time.perf_counter() - start

    return timed_fit


__all__ = ["fqi_seconds", "timed"]
