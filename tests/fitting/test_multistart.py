"""The multistart portfolio's parts (``fitting.multistart``, issue 25, item 3): seeded draws,
and how many starts reached the best, judged on one scale."""

import math

import numpy as np

from hframe_id.fitting.multistart import (
    SPREAD,
    StartOutcome,
    reached_best,
    seeded_starts,
    statement,
)


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
