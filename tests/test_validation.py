"""Known answers of tatl_mj.validation: what passes, what is refused, and the message."""

import math
import re

import numpy as np
import pytest

from tatl_mj import validation


@pytest.mark.parametrize("value", [0, 3, -2, np.int64(5), np.uint8(1)])
def test_is_integer_accepts_ints_and_numpy_integers(value):
    assert validation.is_integer(value)


@pytest.mark.parametrize("value", [True, False, np.bool_(True), 2.0, "3", None, np.float64(1.0)])
def test_is_integer_refuses_bools_floats_and_others(value):
    assert not validation.is_integer(value)


@pytest.mark.parametrize("value", [0, -1.5, 2.0, np.float32(0.5), np.int64(3)])
def test_is_number_accepts_finite_reals(value):
    assert validation.is_number(value)


@pytest.mark.parametrize("value", [True, math.nan, math.inf, -math.inf, "1.0", None, 1j])
def test_is_number_refuses_bools_non_finite_and_others(value):
    assert not validation.is_number(value)


def test_integer_returns_a_plain_int():
    got = validation.integer("Owner", "n", np.int64(4))
    assert got == 4 and type(got) is int


def test_integer_bounds_are_inclusive():
    assert validation.integer("Owner", "n", 2, minimum=2, maximum=5) == 2
    assert validation.integer("Owner", "n", 5, minimum=2, maximum=5) == 5
    with pytest.raises(ValueError, match=re.escape("Owner.n must be an integer in 2..5, got 6")):
        validation.integer("Owner", "n", 6, minimum=2, maximum=5)
    with pytest.raises(ValueError, match=re.escape("Owner.n must be an integer in 2..5, got 1")):
        validation.integer("Owner", "n", 1, minimum=2, maximum=5)


@pytest.mark.parametrize("value", [True, False, 2.0, "2", None])
def test_integer_refuses_bools_and_non_integers(value):
    with pytest.raises(ValueError, match=re.escape(f"Owner.n must be an integer >= 0, got {value!r}")):
        validation.integer("Owner", "n", value, minimum=0)


def test_integer_message_without_owner_and_with_unit():
    with pytest.raises(ValueError) as error:
        validation.integer("", "width", 8, minimum=16, unit=" pixels")
    assert str(error.value) == "width must be an integer >= 16 pixels, got 8"


def test_number_returns_a_plain_float():
    got = validation.number("Owner", "x", np.float32(0.5), 0.0, 1.0)
    assert got == 0.5 and type(got) is float
    assert type(validation.number("Owner", "x", 3)) is float


@pytest.mark.parametrize(
    "low_open, high_open, interval, inside, outside",
    [
        (False, False, "[0, 1]", [0.0, 0.5, 1.0], [-0.1, 1.1]),
        (True, False, "(0, 1]", [1e-12, 1.0], [0.0, 1.5]),
        (False, True, "[0, 1)", [0.0, 0.999], [1.0, -1e-12]),
        (True, True, "(0, 1)", [0.5], [0.0, 1.0]),
    ],
)
def test_number_bounds_open_and_closed(low_open, high_open, interval, inside, outside):
    for value in inside:
        assert validation.number("Owner", "x", value, 0.0, 1.0, low_open, high_open) == value
    for value in outside:
        message = f"Owner.x must be a finite number in {interval}, got {value!r}"
        with pytest.raises(ValueError, match=re.escape(message)):
            validation.number("Owner", "x", value, 0.0, 1.0, low_open, high_open)


@pytest.mark.parametrize(
    "kwargs, valid",
    [
        (dict(), ""),
        (dict(low=0.0), " >= 0"),
        (dict(low=0.0, low_open=True), " > 0"),
        (dict(high=2.5), " <= 2.5"),
        (dict(high=2.5, high_open=True), " < 2.5"),
    ],
)
def test_number_message_names_one_sided_ranges(kwargs, valid):
    with pytest.raises(ValueError) as error:
        validation.number("Owner", "x", math.nan, **kwargs)
    assert str(error.value) == f"Owner.x must be a finite number{valid}, got nan"


@pytest.mark.parametrize("value", [True, math.inf, "0.5", None])
def test_number_refuses_bools_non_finite_and_non_numbers(value):
    with pytest.raises(ValueError, match="Owner.x must be a finite number"):
        validation.number("Owner", "x", value)


def test_number_unit_follows_the_range():
    with pytest.raises(ValueError) as error:
        validation.number("P", "ratio", -2.0, 0.0, low_open=True, unit=" (dt_source / dt_target)")
    assert str(error.value) == "P.ratio must be a finite number > 0 (dt_source / dt_target), got -2.0"


def test_choice():
    assert validation.choice("Owner", "kind", "b", ("a", "b")) == "b"
    with pytest.raises(ValueError) as error:
        validation.choice("Owner", "kind", "c", ("a", "b"))
    assert str(error.value) == "Owner.kind must be one of ['a', 'b'], got 'c'"
