"""A multistart portfolio fitted whole (``fitting.multistart``): the best kept and every start
reported, in the summary and the ``--json`` object."""

from hframe_id.fitting import FitOptions, fit_recordings
from hframe_id.fitting.multistart import reached_best
from hframe_id.fitting.summary_json import fit_summary

FREE = ("k_l", "M_cart", "b_cart", "F_c_cart")


def test_a_portfolio_keeps_the_best_and_reports_every_start(table, x_step):
    truth = table.replace_values(k_l=12500.0, M_cart=1.15, F_c_cart=0.3)
    steps = [x_step(truth, seed=3), x_step(truth, seed=4, volts=-4.0)]
    result = fit_recordings(steps, table, FitOptions(free=FREE, starts=3, start_seed=1))
    assert result.success, result.message
    outcomes = result.diagnostics.starts
    assert [o.label for o in outcomes][0] == "the start" and len(outcomes) == 3
    # Matched data from a start within x/÷2: every start finds the truth's optimum.
    assert reached_best(outcomes) == 3
    # Reported from the point the fit began from (the start screen's), whichever start won.
    assert result.initial is result.diagnostics.start_screen.parameters
    assert "multistart: 3 of 3 starts" in result.summary()
    assert fit_summary(result, "fit-id", None, None)["starts"]["reached_best"] == 3
