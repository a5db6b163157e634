"""Intervals widened by the uncertainty of held parameters (``fitting.held_uncertainty``),
through two small fits: held values exact, then k_r held with a +/-20 % prior."""

import math

import pytest

from hframe_id.fitting import FitOptions, fit_recordings


@pytest.fixture(scope="module")
def fits(table, steps):
    """k_l fitted to the two steps with every held value exact, then with k_r's prior."""
    exact = fit_recordings(steps, table, FitOptions(free=("k_l",), consider={}))
    held = fit_recordings(steps, table, FitOptions(free=("k_l",), consider={"k_r": 0.2}))
    return exact, held


def test_held_values_taken_as_exact_add_nothing_and_say_nothing(fits):
    exact, _ = fits
    assert exact.success, exact.message
    assert exact.diagnostics.consider.held_relative_std == {}
    assert exact.held_statement() is None


def test_a_held_prior_adds_its_variance_to_the_free_parameters(fits, table):
    """k_l is log-scale: its relative std becomes sqrt(std^2 + added^2), the interval
    symmetric in log p at that std (same optimum: the prior moves no estimate)."""
    exact, held = fits
    assert held.success, held.message
    consider = held.diagnostics.consider
    assert consider.held_relative_std == {"k_r": 0.2} and consider.method == "linear"
    added = consider.relative_std_added["k_l"]
    assert added > 0
    before, after = exact.estimates["k_l"], held.estimates["k_l"]
    assert after.estimate == pytest.approx(before.estimate, rel=1e-12)
    assert after.relative_std == pytest.approx(math.hypot(before.relative_std, added), rel=1e-9)
    z = held.statistics.z_value(held.options.confidence)
    factor = math.exp(z * after.relative_std)
    assert after.ci95 == pytest.approx((after.estimate / factor, after.estimate * factor))
    assert f"k_r = {table.values['k_r']:.4g} (+/-20 %)" in held.held_statement()
