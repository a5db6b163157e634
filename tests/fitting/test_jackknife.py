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


def test_jackknife_intervals_come_in_a_new_result_and_the_fit_is_left_as_it_was():
    """Two converged folds: the determined parameter gets its jackknife interval in a new
    result; the one held for identifiability does not; the fit's own result is unchanged."""
    from types import SimpleNamespace

    import numpy as np

    from hframe_id.fitting import FitOptions
    from hframe_id.fitting.jackknife import with_jackknife_intervals
    from hframe_id.fitting.result import FitResult, ParameterEstimate

    def estimate(name):
        return ParameterEstimate(name, "N/m", 1.0, 2.0, 0.1, (1.8, 2.2), True, True)

    result = FitResult(
        success=True,
        message="converged",
        parameters=None,
        estimates={"k_l": estimate("k_l"), "k_r": estimate("k_r")},
        cost=1.0,
        iterations=1,
        wall_time_s=0.0,
        correlation=np.eye(2),
        free_names=("k_l", "k_r"),
        initial=None,
        options=FitOptions(),
        not_identified=("k_r",),
        problem=SimpleNamespace(free_names=("k_l", "k_r"), linear=np.array([False, False])),
    )
    fold = SimpleNamespace(success=True)
    rows = [SimpleNamespace(name=n, jackknife_std=0.1) for n in ("k_l", "k_r")]
    table = SimpleNamespace(folds=[fold, fold], spread=rows)
    updated = with_jackknife_intervals(result, table)
    assert updated is not result
    assert updated.estimates["k_l"].jackknife_ci95 == pytest.approx(
        jackknife_interval(2.0, 0.1, 2, signed=False, confidence=0.95)
    )
    assert updated.estimates["k_r"].jackknife_ci95 is None
    assert result.estimates["k_l"].jackknife_ci95 is None
