"""Experiment-level jackknife intervals (fitting.jackknife) beside the fit's own."""

import math

import pytest

from hframe_id.fitting.jackknife import jackknife_interval, student_t_quantile


def test_student_t_quantiles_are_the_tables():
    # Standard t-table values (4 decimals): 12.7062 (1 dof), 2.5706 (5), 2.2281 (10).
    for dof, expected in ((1, 12.7062), (5, 2.5706), (10, 2.2281)):
        assert student_t_quantile(0.975, dof) == pytest.approx(expected, abs=5e-5)


def test_jackknife_interval_is_symmetric_in_log_and_linear_when_signed():
    t = student_t_quantile(0.975, 5)
    low, high = jackknife_interval(2.0, 0.1, 6, signed=False, confidence=0.95)
    assert math.log(high / 2.0) == pytest.approx(math.log(2.0 / low))
    assert math.log(high / 2.0) == pytest.approx(t * 0.1 / 2.0)
    assert jackknife_interval(-1.0, 0.1, 6, signed=True, confidence=0.95) == pytest.approx(
        (-1.0 - t * 0.1, -1.0 + t * 0.1)
    )
