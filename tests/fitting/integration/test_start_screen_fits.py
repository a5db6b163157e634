"""Whole fits begin from the best point they know (``fitting.start_screen``), and say so."""

from hframe_id.fitting import FitOptions, fit_recordings
from hframe_id.fitting.summary_json import fit_summary

#: A small free set (stiffness, mass, viscous and Coulomb friction) for fast fits.
FREE = ("k_l", "k_r", "M_cart", "b_cart", "F_c_cart")


def test_a_fit_from_a_poor_start_begins_from_a_better_point_it_knows(table, steps):
    start = table.replace_values(M_cart=2 * table.values["M_cart"], k_l=3e4)
    result = fit_recordings(steps, start, FitOptions(free=FREE))
    assert result.success, result.message
    screen = result.diagnostics.start_screen
    # Table 4.2 (near the plant) beats the start, and the best of the points began the fit.
    assert screen.criteria["hframe-8-table4.2.yaml"] < screen.criteria["the start"]
    assert screen.moved and screen.criteria[screen.label] == min(screen.criteria.values())
    assert f"began from {screen.label}" in result.message
    # The file and the report name the point the fit began from as its start.
    assert result.initial is screen.parameters
    assert result.estimates["M_cart"].initial == screen.parameters.values["M_cart"]
    summary = fit_summary(result, "test", None, None)
    assert summary["began_from"]["label"] == screen.label
    assert summary["began_from"]["criteria"] == screen.criteria
    # Matched data: the answer is the plant's, whichever point the fit began from.
    given = fit_recordings(steps, start, FitOptions(free=FREE, screen_start=False))
    assert given.success, given.message
    assert given.diagnostics.start_screen.skipped == "off"
    assert "began from" not in given.message
    for name in FREE:
        # Within 0.1 % of each other: the same optimum (matched data, one basin).
        assert abs(result.parameters.values[name] / given.parameters.values[name] - 1) < 1e-3
