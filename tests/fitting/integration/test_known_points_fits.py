"""Whole fits never worse than a point they know (issue 25, item 2), and the box they search
(``fitting.fit``, ``fitting.known_points``)."""

from dataclasses import replace

import numpy as np
import pytest

from hframe_id.fitting import FitOptions, fit_recordings
from hframe_id.fitting import fit as fit_module
from hframe_id.fitting.known_points import simulation_criterion

#: A small free set (stiffness, mass, viscous and Coulomb friction) for fast fits.
FREE = ("k_l", "k_r", "M_cart", "b_cart", "F_c_cart")
#: The fits that test what happens at the end begin at their start, not at a better known
#: point (``fitting.start_screen``, tested in test_start_screen_fits.py).
GIVEN = {"screen_start": False}


def test_the_fit_is_compared_with_what_it_knows(table, truth, steps):
    result = fit_recordings(steps, table, FitOptions(free=FREE, known_points=(truth,)))
    assert result.success, result.message
    report = result.diagnostics.known_points
    points = report.points
    assert {"the start", "the equation-error estimate", "hframe-8-table4.1.yaml"} <= set(points)
    assert any(label.startswith("known point 1") for label in points)
    # Matched data: the fit is the best of them, its truth included.
    assert report.fit <= min(report.compared.values())
    assert "the best known point" in result.summary()


def _stopping_early(monkeypatch, table, outcome):
    """``_fit_widening`` returning the start's parameters as a 'successful' fit (a solver
    that stopped at once) for the first call, then ``outcome(start)``."""
    real = fit_module._fit_widening
    calls = []

    def fake(recordings, initial, options, screened=False):
        calls.append(initial)
        result = real(recordings, initial, options, screened)
        if len(calls) == 1:
            result = replace(
                result, parameters=table.replace_values(**{n: table.values[n] for n in FREE})
            )
        else:
            result = outcome(result)
        return result

    monkeypatch.setattr(fit_module, "_fit_widening", fake)
    return calls


def test_a_fit_worse_than_a_known_point_continues_from_it(monkeypatch, table, truth, steps):
    calls = _stopping_early(monkeypatch, table, lambda result: result)
    result = fit_recordings(steps, table, FitOptions(free=FREE, known_points=(truth,), **GIVEN))
    assert len(calls) == 2
    assert result.success, result.message
    assert "continued from" in result.message
    report = result.diagnostics.known_points
    continued = next(iter(report.continued.values()))
    assert continued <= min(report.compared.values())


def test_a_fit_that_stays_worse_fails_saying_so(monkeypatch, table, truth, steps):
    def still_at_the_start(result):
        return replace(result, parameters=table)

    _stopping_early(monkeypatch, table, still_at_the_start)
    result = fit_recordings(steps, table, FitOptions(free=FREE, known_points=(truth,), **GIVEN))
    assert not result.success
    assert "the fit ends worse than" in result.message
    std = dict(result.diagnostics.channel_std)
    assert simulation_criterion(table, steps, std) > simulation_criterion(truth, steps, std)


def test_a_default_box_that_stops_the_fit_is_widened(table, steps, truth):
    """k_l 0.95 x the start: outside x/÷1.02 and 1.02^2, inside 1.02^4."""
    options = FitOptions(free=("k_l",), bound_factor=1.02)
    result = fit_recordings(steps, table.replace_values(M_cart=1.15, F_c_cart=0.3), options)
    assert result.success, result.message
    assert result.parameters.values["k_l"] == pytest.approx(truth.values["k_l"], rel=1e-3)
    assert not result.estimates["k_l"].at_bound


def test_a_fit_still_on_the_widened_box_fails_saying_so(table, steps):
    """k_l 0.95 x the start; boxes of x/÷1.001, 1.001^2 and 1.001^4."""
    options = FitOptions(free=("k_l",), bound_factor=1.001)
    result = fit_recordings(steps, table.replace_values(M_cart=1.15, F_c_cart=0.3), options)
    assert not result.success
    assert "the default box decided the answer: k_l" in result.message


def test_a_given_bound_is_the_users_decision(table, steps):
    options = FitOptions(free=("k_l",), bounds={"k_l": (12600.0, 13200.0)})
    result = fit_recordings(steps, table.replace_values(M_cart=1.15, F_c_cart=0.3), options)
    assert result.success, result.message
    assert result.estimates["k_l"].at_bound
    assert result.diagnostics.at_default_box == ()


def test_a_fit_that_fails_from_its_start_continues_from_a_known_point(table, steps, truth):
    """k_l 0.95 x the start, boxes of x/÷1.001 (widened twice): the fit from the start fails
    on the box; the truth, named as a known point, is not clipped into that box, and the fit
    from it succeeds."""
    start = table.replace_values(M_cart=1.15, F_c_cart=0.3)
    options = FitOptions(free=("k_l",), bound_factor=1.001, known_points=(truth,), **GIVEN)
    result = fit_recordings(steps, start, options)
    assert result.success, result.message
    assert "continued from known point 1" in result.message
    assert "where the first fit failed" in result.message
    assert result.parameters.values["k_l"] == pytest.approx(truth.values["k_l"], rel=1e-3)
    assert result.initial is start
    report = result.diagnostics.known_points
    label = "known point 1 (H-frame 8th-order model, nonlinear friction)"
    assert report.fit == report.continued[label]  # the criterion of the parameters written
    assert report.fit <= report.points[label]


def test_a_failed_fit_is_also_judged_from_the_replays_rest_state(table, steps):
    """A converged fit's points are judged from its estimated initial states; a failed fit's
    also from what ``validate`` replays, None (the replay's rest state) for the steps, which
    start at rest; a point's criterion is then the lower. A fit whose last solve started its
    records at rest from the replay's rest state is judged from there, named None."""
    from hframe_id.fitting.known_points import Criterion, judged_starts

    result = fit_recordings(steps[:1], table, FitOptions(free=("k_l",)))
    assert result.success and all(e.at_rest for e in result.problem.experiments)
    assert result.options.rest_start == "replay"  # its last solve ran
    assert judged_starts(result) == ([None],)
    estimated = replace(result, options=replace(result.options, rest_start="rigid"))
    (own,) = judged_starts(estimated)
    assert np.array_equal(own[0], result.initial_states[0])
    failed = replace(estimated, success=False)
    own, replay = judged_starts(failed)
    assert replay == [None]
    criterion = Criterion.of(result, steps[:1])
    both = criterion(result.parameters, (own, replay))
    assert both == min(criterion(result.parameters, (own,)), criterion(result.parameters))
