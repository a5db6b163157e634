"""The fit's last solve starts each record at rest where ``validate`` replays it from
(``fitting.replayed_rest``): what the fit reports is what the written file reproduces."""

from dataclasses import replace

import numpy as np
import pytest

from hframe_id.fitting import FitOptions, fit_recordings, replayed_rest
from hframe_id.models import build_model
from hframe_id.validation.replay import channels, rest_state

#: A small free set (stiffness, mass, viscous and Coulomb friction) for fast fits.
FREE = ("k_l", "k_r", "M_cart", "b_cart", "F_c_cart")


@pytest.fixture(scope="module")
def fitted(table, steps):
    return fit_recordings(steps, table, FitOptions(free=FREE))


def test_the_fit_ends_from_the_replays_rest_state(fitted, steps):
    assert fitted.success, fitted.message
    assert fitted.stages[-1].name == replayed_rest.STAGE
    model = build_model("hframe-8")
    p = np.array([fitted.parameters.values[n] for n in model.parameter_names])
    for rec, x0 in zip(steps, fitted.initial_states, strict=True):
        # The state validate starts the record from, up to rounding (computed at the
        # parameters the last solve began from; 1e-15 m or rad is 1e-9 of an encoder step).
        expected = rest_state(model, p, channels(model, rec))
        np.testing.assert_allclose(x0, expected, rtol=0, atol=1e-15)
    # So the criterion the fit reports is the one its file replays (within 1e-6 chi^2 / 2).
    report = fitted.diagnostics.known_points
    assert report.fit == pytest.approx(report.replayed, abs=1e-6)


def test_no_last_solve_where_the_stages_fixed_the_rest_state(table, steps, fitted):
    given = fit_recordings(steps, table, FitOptions(free=FREE, rest_start="replay"))
    assert given.success, given.message
    assert all(s.name != replayed_rest.STAGE for s in given.stages)
    # The same optimum by either path (matched data): chi^2 / 2 within 0.01 of each other,
    # a hundredth of the 1.92 that a likelihood-ratio test at 95 % could tell apart.
    assert given.cost == pytest.approx(fitted.cost, abs=0.01)


@pytest.fixture()
def stalling_last_solve(monkeypatch):
    """The last solve run as it is, then reported as stopped unconverged."""
    real = replayed_rest.warm_solve

    def stalling(run, start, label, *interrupts):
        state, gn = real(run, start, label, *interrupts)
        run.stages[-1] = replace(
            run.stages[-1], converged=False, message="not converged in 0 iterations"
        )
        return state, gn

    monkeypatch.setattr(replayed_rest, "warm_solve", stalling)


def test_an_unconverged_last_solve_that_replays_better_is_kept(stalling_last_solve, table, steps):
    result = fit_recordings(steps, table, FitOptions(free=FREE))
    assert result.success, result.message
    assert result.stages[-2].name == replayed_rest.STAGE and not result.stages[-2].converged
    assert result.stages[-1].name == f"{replayed_rest.STAGE}: kept unconverged"
    assert "stopped unconverged" in result.message
    # What the fit reports is what its file replays (within 1e-6 chi^2 / 2).
    report = result.diagnostics.known_points
    assert report.fit == pytest.approx(report.replayed, abs=1e-6)


def test_an_unconverged_last_solve_that_replays_no_better_is_rejected(
    stalling_last_solve, monkeypatch, table, steps
):
    # A judge that finds every end the same: the last solve's is then no better.
    monkeypatch.setattr(replayed_rest, "_replay_criterion", lambda problem, recordings: len)
    result = fit_recordings(steps, table, FitOptions(free=FREE))
    assert result.success, result.message
    assert result.stages[-1].name == f"{replayed_rest.STAGE}: rejected"
    assert "the fit keeps the belt-free positions it estimated" in result.message
    # Its initial positions are the stages' estimates, not the replay's rest state.
    report = result.diagnostics.known_points
    assert report.fit != report.replayed
