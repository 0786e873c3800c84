"""Checks of settings and arguments, done once where they enter.

A class with settings declares what each admits once, in a class-level table
``constraints`` (field -> list of constraints; a value is valid if any of them
admits it, and ``None`` in the list admits None, written ``"none"`` in a spec,
whose TOML has no null)::

    constraints: ClassVar[Constraints] = {
        "zeta": [None, Interval(float, 0, closed="right")],
        "gap": [Options("absolute", "relative")],
    }

and :func:`check_settings` checks and converts them (lists to tuples, ints to
floats where a float is declared, ``"none"`` to None), raising
:class:`InvalidSetting` with one line: ``Owner.field must be <what the
constraints admit>, got <value>``. The vocabulary is :class:`Interval`,
:class:`Options`, :class:`Boolean`, :class:`Text`, :class:`ListOf`,
:class:`Array` and :class:`Function`; a subclass of :class:`Constraint` is a new
word (``tatl_mj.transfer.features.FeaturesSpec``). Cross-field rules (a setting
that applies to one regressor only) stay in the class, after the table's checks.

:func:`integer`, :func:`number` and :func:`choice` check one argument of a plain
function (``owner=""`` drops the ``Owner.`` prefix). Objects built from checked
settings trust them and do not check again.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

NONE = "none"
"""How a spec (TOML, which has no null) says None for a setting whose constraints admit None
(``zeta = "none"``: Algorithm 2 off, the apprentice fitted on every sample)."""


class InvalidSetting(ValueError):
    """A setting or argument outside what its constraints admit; one line naming ``owner.field``."""


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


class Constraint:
    """What one setting admits, in words (``str``) and as a check.

    A subclass implements :meth:`convert`: the value in its plain type, or
    ``ValueError`` (its message, if any, says why) where it is not admitted; and
    :meth:`invalid`: a value it refuses, so that one test can try every
    declared constraint of every method.
    """

    def convert(self, value: Any) -> Any:
        raise NotImplementedError

    def invalid(self) -> Any:
        raise NotImplementedError

    def admits(self, value: Any) -> bool:
        try:
            self.convert(value)
        except ValueError:
            return False
        return True

    def __repr__(self) -> str:
        return f"<{type(self).__name__}: {self}>"


Constraints = dict[str, list[Constraint | None]]
"""A class's ``constraints`` table: setting -> what it admits (any one of the list)."""

_CLOSED = ("both", "left", "right", "neither")


def _bound(value: float | None) -> str:
    return f"{value:g}"


class Interval(Constraint):
    """An integer (``kind=int``) or a finite number (``kind=float``; an int is taken as a float)
    between ``low`` and ``high`` (None: unbounded); ``closed`` says which bounds belong
    ("both", "left", "right", "neither"); ``unit`` follows the range in messages."""

    def __init__(
        self,
        kind: type,
        low: float | None = None,
        high: float | None = None,
        closed: str = "both",
        unit: str = "",
    ) -> None:
        if kind not in (int, float) or closed not in _CLOSED:
            raise ValueError(f"Interval(kind in (int, float), closed in {_CLOSED}), got {kind!r}, {closed!r}")
        self.kind, self.low, self.high, self.closed, self.unit = kind, low, high, closed, unit

    def _inside(self, value: float) -> bool:
        low_in = self.closed in ("both", "left")
        high_in = self.closed in ("both", "right")
        above = self.low is None or self.low < value or (low_in and value == self.low)
        below = self.high is None or value < self.high or (high_in and value == self.high)
        return above and below

    def convert(self, value: Any) -> Any:
        if self.kind is int:
            if not is_integer(value) or not self._inside(value):
                raise ValueError
            return int(value)
        if not is_number(value) or not self._inside(value):
            raise ValueError
        return float(value)

    def invalid(self) -> Any:
        if self.low is not None:
            return self.low - 1
        if self.high is not None:
            return self.high + 1
        return 0.5 if self.kind is int else math.nan

    def _range(self) -> str:
        low_in, high_in = self.closed in ("both", "left"), self.closed in ("both", "right")
        if self.low is None and self.high is None:
            return ""
        if self.high is None:
            return f" {'>=' if low_in else '>'} {_bound(self.low)}"
        if self.low is None:
            return f" {'<=' if high_in else '<'} {_bound(self.high)}"
        if self.kind is int and self.closed == "both":
            return f" in {_bound(self.low)}..{_bound(self.high)}"
        return f" in {'[' if low_in else '('}{_bound(self.low)}, {_bound(self.high)}{']' if high_in else ')'}"

    def __str__(self) -> str:
        return f"{'an integer' if self.kind is int else 'a finite number'}{self._range()}{self.unit}"


class Options(Constraint):
    """One of the given values (strings, usually)."""

    def __init__(self, *values: Any) -> None:
        self.values = values

    def convert(self, value: Any) -> Any:
        if not isinstance(value, (str, int, float, bool, type(None))) or value not in self.values:
            raise ValueError
        return value

    def invalid(self) -> Any:
        return f"not-{self.values[0]}" if self.values else "anything"

    def __str__(self) -> str:
        return f"one of {list(self.values)}"


class Boolean(Constraint):
    """``true`` or ``false`` (a bool or a numpy bool; not 0 or 1)."""

    def convert(self, value: Any) -> Any:
        if not isinstance(value, (bool, np.bool_)):
            raise ValueError
        return bool(value)

    def invalid(self) -> Any:
        return "yes"

    def __str__(self) -> str:
        return "true or false"


class Text(Constraint):
    """A string; ``what`` says which (``"a state name"``)."""

    def __init__(self, what: str = "a string") -> None:
        self.what = what

    def convert(self, value: Any) -> Any:
        if not isinstance(value, str):
            raise ValueError
        return value

    def invalid(self) -> Any:
        return 0

    def __str__(self) -> str:
        return self.what


class ListOf(Constraint):
    """A list (TOML array) or tuple, each entry admitted by ``item``, as a tuple (settings are
    frozen). ``nonempty``: at least one entry; ``not_all_zero``: a non-empty one has an entry
    other than 0."""

    def __init__(self, item: Constraint, nonempty: bool = False, not_all_zero: bool = False) -> None:
        self.item, self.nonempty, self.not_all_zero = item, nonempty, not_all_zero

    def convert(self, value: Any) -> Any:
        if not isinstance(value, (list, tuple)) or (self.nonempty and not value):
            raise ValueError
        entries = tuple(self.item.convert(v) for v in value)
        if self.not_all_zero and entries and all(v == 0 for v in entries):
            raise ValueError
        return entries

    def invalid(self) -> Any:
        return (self.item.invalid(),)

    def __str__(self) -> str:
        return f"a {'non-empty ' if self.nonempty else ''}list, each entry {self.item}" + (
            ", not all 0" if self.not_all_zero else ""
        )


class Array(Constraint):
    """A non-empty numpy array of ``ndim`` 1 (a scalar: one entry) or 2 (a 1-D one: a column)
    as float64. ``finite``: no inf (NaN is always refused); ``low``: each entry >= low (> with
    ``low_open``); ``not_all_zero``: some entry other than 0."""

    def __init__(
        self,
        ndim: int,
        finite: bool = True,
        low: float | None = None,
        low_open: bool = False,
        not_all_zero: bool = False,
    ) -> None:
        self.ndim, self.finite, self.low, self.low_open, self.not_all_zero = ndim, finite, low, low_open, not_all_zero

    def convert(self, value: Any) -> Any:
        if isinstance(value, (str, bytes, dict)):
            raise ValueError
        try:
            a = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError from None
        a = np.atleast_1d(a) if self.ndim == 1 else (a[:, None] if a.ndim == 1 else a)
        bad = a.ndim != self.ndim or a.size == 0 or np.any(np.isnan(a)) or (self.finite and not np.all(np.isfinite(a)))
        if not bad and self.low is not None:
            bad = bool(np.any(a <= self.low) if self.low_open else np.any(a < self.low))
        if bad or (self.not_all_zero and not np.any(a != 0)):
            raise ValueError
        return a

    def invalid(self) -> Any:
        return np.full((1,) * self.ndim, np.nan)

    def __str__(self) -> str:
        entries = "finite numbers" if self.finite else "numbers (no NaN)"
        if self.low is not None:
            entries += f" {'>' if self.low_open else '>='} {_bound(self.low)}"
        return f"a non-empty {self.ndim}-D array of {entries}" + (", not all 0" if self.not_all_zero else "")


class Function(Constraint):
    """A callable; ``what`` says its signature (``"(states (N, d), actions (N, m)) -> (N, d)"``)."""

    def __init__(self, what: str = "") -> None:
        self.what = what

    def convert(self, value: Any) -> Any:
        if not callable(value):
            raise ValueError
        return value

    def invalid(self) -> Any:
        return 0

    def __str__(self) -> str:
        return f"a callable {self.what}".rstrip()


def _shown(value: Any) -> str:
    """``value`` in one short line: an array by its shape, anything else by a repr cut at 200 characters."""
    if isinstance(value, np.ndarray) and value.size > 8:
        return f"an array of shape {value.shape}"
    text = " ".join(repr(value).split())
    return text if len(text) <= 200 else text[:197] + "..."


def describe(allowed: list[Constraint | None]) -> str:
    """What a list of constraints admits, in words (``a finite number > 0 or None ("none" in a spec)``)."""
    words = [str(c) for c in allowed if c is not None]
    return " or ".join(words + (['None ("none" in a spec)'] if None in allowed else []))


def check(owner: str, field: str, value: Any, allowed: list[Constraint | None]) -> Any:
    """``value`` converted by the first of ``allowed`` that admits it (None admits None and
    ``"none"``); :class:`InvalidSetting` naming ``owner.field``, what is valid and ``value``
    if none does."""
    if None in allowed and (value is None or (isinstance(value, str) and value == NONE)):
        return None
    reasons = []
    for constraint in allowed:
        if constraint is None:
            continue
        try:
            return constraint.convert(value)
        except ValueError as refusal:
            reasons += [str(refusal)] if str(refusal) else []
    name = f"{owner}.{field}" if owner else field
    why = f" ({'; '.join(reasons)})" if reasons else ""
    raise InvalidSetting(f"{name} must be {describe(allowed)}, got {_shown(value)}{why}")


def checked_settings(cls: type, settings: dict[str, Any]) -> dict[str, Any]:
    """``settings`` for ``cls``, each one ``cls.constraints`` declares checked and converted
    (the others as given: an unknown one is the constructor's to refuse)."""
    table: Constraints = getattr(cls, "constraints", {})
    return {k: check(cls.__name__, k, v, table[k]) if k in table else v for k, v in settings.items()}


def check_settings(obj: Any) -> None:
    """Checks every setting ``type(obj).constraints`` declares, storing its converted value on
    ``obj`` (a frozen dataclass, from its ``__post_init__``)."""
    owner = type(obj)
    table: Constraints = getattr(owner, "constraints", {})
    for field, allowed in table.items():
        value = getattr(obj, field)
        converted = check(owner.__name__, field, value, allowed)
        if converted is not value:
            object.__setattr__(obj, field, converted)  # frozen: the one place settings are converted


def integer(owner: str, field: str, value: Any, minimum: int = 1, maximum: int | None = None, unit: str = "") -> int:
    """``value`` as an int, if it is an integer in ``minimum..maximum`` (None: no upper bound).

    ``unit`` is appended to the valid range in the message, e.g. ``" (target steps)"``.
    """
    return check(owner, field, value, [Interval(int, minimum, maximum, unit=unit)])


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
    closed = _CLOSED[2 * low_open + high_open]
    bounds = (None if low == -math.inf else low, None if high == math.inf else high)
    return check(owner, field, value, [Interval(float, *bounds, closed=closed, unit=unit)])


def choice(owner: str, field: str, value: Any, valid: tuple) -> Any:
    """``value``, if it is one of ``valid``."""
    return check(owner, field, value, [Options(*valid)])


__all__ = [
    "NONE",
    "Array",
    "Boolean",
    "Constraint",
    "Constraints",
    "Function",
    "Interval",
    "InvalidSetting",
    "ListOf",
    "Options",
    "Text",
    "check",
    "check_settings",
    "checked_settings",
    "choice",
    "describe",
    "integer",
    "is_integer",
    "is_number",
    "number",
]
