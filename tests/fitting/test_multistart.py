"""The multistart portfolio (issue 25, item 3): seeded draws, judged on one scale, the best
kept and how many reached it reported."""

import math

import numpy as np
import pytest

from hframe_id.errors import OptionError
from hframe_id.fitting import FitOptions, fit_recordings
from hframe_id.fitting.multistart import (
    SPREAD,
    StartOutcome,
    reached_best,
    seeded_starts,
    statement,
)
from hframe_id.fitting.summary_json import fit_summary

FREE = ("k_l", "M_cart", "b_cart", "F_c_cart")


def test_the_draws_are_seeded_spread_and_clipped(table):
    kinds = {"k_l": "positive", "M_cart": "positive", "F_0": "real"}
    free = ("k_l", "M_cart")
    starts = seeded_starts(table, free, kinds, 40, 7, {"M_cart": (0.9, 1.2)})
    assert starts[0] == ("the start", table)
    again = seeded_starts(table, free, kinds, 40, 7, {"M_cart": (0.9, 1.2)})
    assert [p.values for _, p in starts] == [p.values for _, p in again]
    ratios = np.array([p.values["k_l"] / table.values["k_l"] for _, p in starts[1:]])
    assert SPREAD[0] <= ratios.min() and ratios.max() <= SPREAD[1]
    assert ratios.min() < 0.7 and ratios.max() > 1.4  # 39 log-uniform draws span the range
    masses = [p.values["M_cart"] for _, p in starts[1:]]
    assert min(masses) >= 0.9 and max(masses) <= 1.2
    assert {0.9, 1.2} <= set(masses)  # x/÷2 of 1.04 kg leaves the bounds often


def test_real_parameters_keep_the_start(table):
    kinds = {"F_c_cart": "real"}  # as an offset would be
    (_, first), (_, drawn) = seeded_starts(table, ("F_c_cart",), kinds, 2, 0, {})
    assert drawn.values["F_c_cart"] == first.values["F_c_cart"]


def test_reached_best_is_a_likelihood_ratio_test():
    outcomes = [
        StartOutcome("a", True, 100.0),
        StartOutcome("b", True, 101.9),  # within 1.92
        StartOutcome("c", True, 102.0),
        StartOutcome("d", False, math.inf),
    ]
    assert reached_best(outcomes) == 2
    assert reached_best([StartOutcome("d", False, math.inf)]) == 0
    line = statement(outcomes)
    assert line.startswith("multistart: 2 of 4 starts reached the best optimum")
    assert "from a" in line and "d: failed" in line


def test_starts_must_be_a_positive_whole_number():
    with pytest.raises(OptionError, match="starts"):
        FitOptions(starts=0)
    with pytest.raises(OptionError, match="start_seed"):
        FitOptions(start_seed=-1)


def test_a_portfolio_keeps_the_best_and_reports_every_start(table, x_step):
    truth = table.replace_values(k_l=12500.0, M_cart=1.15, F_c_cart=0.3)
    steps = [x_step(truth, seed=3), x_step(truth, seed=4, volts=-4.0)]
    result = fit_recordings(steps, table, FitOptions(free=FREE, starts=3, start_seed=1))
    assert result.success, result.message
    outcomes = result.diagnostics.starts
    assert [o.label for o in outcomes][0] == "the start" and len(outcomes) == 3
    # Matched data from a start within x/÷2: every start finds the truth's optimum.
    assert reached_best(outcomes) == 3
    assert result.initial is table  # reported from the user's start, whichever won
    assert "multistart: 3 of 3 starts" in result.summary()
    assert fit_summary(result, "fit-id", None, None)["starts"]["reached_best"] == 3
