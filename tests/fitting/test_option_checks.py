"""The one-line checks of option values (``fitting.option_checks``): what each accepts, the
message each refuses with (the option's name and the value given), and what a set of
settings changes from its defaults."""

import math
import re
from dataclasses import dataclass

import numpy as np
import pytest

from hframe_id.errors import OptionError
from hframe_id.fitting.option_checks import (
    as_tuple,
    changed_fields,
    check_numbers,
    fraction,
    names,
    nonnegative,
    one_of,
    positive,
)


def _refused(message: str):
    """The whole message, exactly: one line, the option's name and the value as given."""
    return pytest.raises(OptionError, match=f"^{re.escape(message)}$")


@pytest.mark.parametrize(
    ("check", "value", "message"),
    [
        (positive, 0, "n must be > 0, got 0"),
        (positive, -1.5, "n must be > 0, got -1.5"),
        (positive, math.nan, "n must be a finite number > 0, got nan"),
        (positive, math.inf, "n must be a finite number > 0, got inf"),
        (nonnegative, -1, "n must be >= 0, got -1"),
        (nonnegative, math.inf, "n must be a finite number >= 0, got inf"),
        (fraction, 1.0, "n must be < 1, got 1.0"),
        (fraction, 0, "n must be > 0, got 0"),
    ],
)
def test_a_number_out_of_range_is_refused_naming_the_option_and_the_value(check, value, message):
    with _refused(message):
        check("n", value)


@pytest.mark.parametrize(
    ("check", "value", "integer", "message"),
    [
        (positive, True, False, "n must be a number, got True"),
        (positive, "1", False, "n must be a number, got '1'"),
        (positive, None, False, "n must be a number, got None"),
        (positive, 2.0, True, "n must be a whole number, got 2.0"),
        (nonnegative, False, True, "n must be a whole number, got False"),
    ],
)
def test_a_bool_a_string_or_a_float_for_a_count_is_not_the_number_asked_for(
    check, value, integer, message
):
    """A bool is an int to Python; as an option value it is a mistake, never a 1 or 0."""
    with _refused(message):
        check("n", value, integer=integer)


def test_values_in_range_pass():
    positive("n", 1e-300)
    positive("n", 3, integer=True)
    nonnegative("n", 0)
    nonnegative("n", 0, integer=True)
    fraction("n", 0.999)
    one_of("mode", "b", ("a", "b"))


def test_a_choice_not_offered_is_refused_listing_the_choices():
    with _refused("mode must be one of a, b, got 'c'"):
        one_of("mode", "c", ("a", "b"))


def test_names_are_returned_as_a_tuple_and_a_single_string_is_refused():
    """A string is a sequence of one-letter names to Python: ``free="k_l"`` would free k, _
    and l; it is refused, as are an empty name and a value with no items."""
    assert names("free", ["k_l", "k_*"]) == ("k_l", "k_*")
    assert names("free", (n for n in ("B_1",))) == ("B_1",)
    assert names("free", []) == ()
    refused = "free must be a sequence of parameter names or patterns, got {}"
    for value, shown in [("k_l", "'k_l'"), (["k_l", ""], "['k_l', '']"), (3, "3"), ([1], "[1]")]:
        with _refused(refused.format(shown)):
            names("free", value)


def test_as_tuple_gives_the_items_or_none_for_a_value_without_items():
    assert as_tuple([1, 2]) == (1, 2)
    assert as_tuple(iter("ab")) == ("a", "b")
    assert as_tuple(3.0) is None and as_tuple(None) is None


@dataclass(frozen=True)
class _Settings:
    """Settings of each kind ``check_numbers`` tells apart."""

    rate: float = 0.5
    count: int = 3
    share: float = 0.25
    floor: float = 0.0
    label: str = "anything"


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"rate": 0.0}, "s.rate must be > 0, got 0.0"),
        ({"count": 2.5}, "s.count must be a whole number, got 2.5"),
        ({"share": 1.0}, "s.share must be < 1, got 1.0"),
        ({"floor": -1.0}, "s.floor must be >= 0, got -1.0"),
    ],
)
def test_check_numbers_checks_each_field_by_its_kind_named_with_the_prefix(changes, message):
    kinds = dict(counts=("count",), fractions=("share",), may_be_zero=("floor",), skip=("label",))
    check_numbers(_Settings(), "s", **kinds)  # the defaults pass, the string is skipped
    with _refused(message):
        check_numbers(_Settings(**changes), "s", **kinds)


def test_changed_fields_are_those_that_differ_from_the_defaults():
    assert changed_fields(_Settings()) == {}
    assert changed_fields(_Settings(rate=0.5, count=4, label="x")) == {"count": 4, "label": "x"}


def test_numpy_numbers_are_accepted_and_recorded_as_plain_data():
    """A count computed with NumPy is a count; the provenance holds Python numbers (a
    parameter file is written by ``yaml.safe_dump``, which refuses NumPy's)."""
    positive("n", np.int64(3), integer=True)
    nonnegative("n", np.float64(0.5))
    changed = changed_fields(_Settings(rate=np.float64(0.25), count=np.int64(4)))
    assert changed == {"rate": 0.25, "count": 4}
    assert [type(v) for v in changed.values()] == [float, int]
