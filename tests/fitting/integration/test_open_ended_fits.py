"""A parameter on the widened default box that the data bound on one side only (issue 25,
item 4: the box decided only the value written, not the predictions)."""

import math
from dataclasses import replace

import pytest

from hframe_id.fitting import FitOptions, fit_recordings
from hframe_id.fitting.open_ended import open_ends
from hframe_id.fitting.resolution import LIKELIHOOD_RATIO_95

#: Sensors a million times noisier than the sim rig's (rad and m): no value of k_l within
#: the box changes the simulated outputs by a visible amount.
DEAF = {"phi1": 5.0, "phi2": 5.0, "x": 5.0, "y": 5.0}
#: Boxes of x/÷1.001, 1.001^2 and 1.001^4 around a start 1.05 x the truth: every fit of k_l
#: ends on the box.
TIGHT = 1.001


@pytest.fixture(scope="module")
def start(truth):
    return truth.replace_values(k_l=1.05 * truth.values["k_l"])


def test_data_that_see_the_parameter_keep_the_box_deciding(start, steps):
    result = fit_recordings(steps, start, FitOptions(free=("k_l",), bound_factor=TIGHT))
    assert not result.success
    assert "the default box decided the answer: k_l" in result.message
    assert "the criterion rises by" in result.message


def test_data_that_do_not_see_it_give_an_open_ended_answer(start, steps):
    options = FitOptions(free=("k_l",), bound_factor=TIGHT, channel_std=DEAF, noise="sensor")
    result = fit_recordings(steps, start, options)
    assert result.success, result.message
    est = result.estimates["k_l"]
    assert est.open_ended == "below"  # the data pull k_l down, towards the truth
    assert est.at_bound and not est.identified
    assert est.ci95 == (0.0, math.inf)
    assert "k_l is not bounded below by the data" in result.message
    assert "at a bound" not in result.message
    assert "not bounded below by the data" in result.summary()


def test_the_scan_stops_where_the_criterion_rises(start, steps):
    """Seen data: the first step back already rises past the threshold; deaf data: the scan
    runs to the far side of the box, every value within the threshold."""
    options = FitOptions(free=("k_l",), bound_factor=TIGHT)
    seen = fit_recordings(steps, start, options)
    (end,) = open_ends(seen, steps, ["k_l"])
    assert end.rise >= LIKELIHOOD_RATIO_95 and not end.open
    assert end.finite_end == end.nearer_value
    deaf = fit_recordings(steps, start, replace(options, channel_std=DEAF))
    (end,) = open_ends(deaf, steps, ["k_l"])
    assert end.open
    factor = deaf.options.bound_factor
    assert end.finite_end == pytest.approx(start.values["k_l"] * factor, rel=1e-12)
