"""Checks of settings and arguments, done once where they enter.

Each check raises ``ValueError`` with one line that names ``owner.field`` (just
``field`` for a plain function argument, ``owner=""``), the bad value and what is
valid; it returns the value in its plain Python type. Objects built from checked
settings trust them and do not check again.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["choice", "integer", "is_integer", "is_number", "number"]


def is_integer(value: Any) -> bool:
    """An int or numpy integer; a bool is not (``True`` would pass as 1)."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def is_number(value: Any) -> bool:
    """A finite int, float or numpy real; a bool is not."""
    return (
        isinstance(value, (int, float, np.integer, np.floating))
        and not isinstance(value, bool)
        and math.isfinite(value)
    )


def _name(owner: str, field: str) -> str:
    return f"{owner}.{field}" if owner else field


def _show(bound: float) -> str:
    return f"{bound:g}"


def integer(owner: str, field: str, value: Any, minimum: int = 1, maximum: int | None = None, unit: str = "") -> int:
    """``value`` as an int, if it is an integer in ``minimum..maximum`` (None: no upper bound).

    ``unit`` is appended to the valid range in the message, e.g. ``" (target steps)"``.
    """
    if not is_integer(value) or value < minimum or (maximum is not None and value > maximum):
        valid = f">= {minimum}" if maximum is None else f"in {minimum}..{maximum}"
        raise ValueError(f"{_name(owner, field)} must be an integer {valid}{unit}, got {value!r}")
    return int(value)


def _interval(low: float, high: float, low_open: bool, high_open: bool) -> str:
    if low == -math.inf and high == math.inf:
        return ""
    if high == math.inf:
        return f" {'>' if low_open else '>='} {_show(low)}"
    if low == -math.inf:
        return f" {'<' if high_open else '<='} {_show(high)}"
    return f" in {'(' if low_open else '['}{_show(low)}, {_show(high)}{')' if high_open else ']'}"


def number(
    owner: str,
    field: str,
    value: Any,
    low: float = -math.inf,
    high: float = math.inf,
    low_open: bool = False,
    high_open: bool = False,
    unit: str = "",
) -> float:
    """``value`` as a float, if it is a finite number between ``low`` and ``high``
    (each bound excluded where its ``_open`` flag is set)."""
    inside = is_number(value) and (low < value or (not low_open and value == low))
    inside = inside and (value < high or (not high_open and value == high))
    if not inside:
        valid = _interval(low, high, low_open, high_open)
        raise ValueError(f"{_name(owner, field)} must be a finite number{valid}{unit}, got {value!r}")
    return float(value)


def choice(owner: str, field: str, value: Any, valid: tuple) -> Any:
    """``value``, if it is one of ``valid``."""
    if value not in valid:
        raise ValueError(f"{_name(owner, field)} is {value!r}; valid choices: {list(valid)}")
    return value
