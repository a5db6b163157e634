"""A parameter on the default box that the data bound on one side only
(``fitting.open_ended``): the likelihood-ratio threshold, the scan through the box and the
sentence for the message, on a stand-in fit whose criterion is given by hand. Whole fits:
integration/test_open_ended_fits.py."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.stats import chi2

from hframe_id.fitting import open_ended
from hframe_id.fitting.open_ended import OpenEnd, _open_end, open_ends
from hframe_id.fitting.resolution import LIKELIHOOD_RATIO_95

#: Start and bound factor of the stand-in fit: boxes x/÷ 16^(1/4), 16^(1/2), 16 give the scan
#: values 100 x/÷ 2, 4, 8, 16, all exact in binary.
START, FACTOR = 100.0, 16.0


def _fit(estimate: float, name: str = "k_l"):
    """A stand-in ``FitResult`` with one positive free parameter ``name`` started at 100 and
    ending at ``estimate``; its ``parameters.replace_values`` gives the changed value."""
    spec = SimpleNamespace(name=name, kind="positive")
    problem = SimpleNamespace(
        model=SimpleNamespace(parameters=[spec]), free_names=(name,), linear=np.array([False])
    )
    return SimpleNamespace(
        problem=problem,
        estimates={name: SimpleNamespace(estimate=estimate, initial=START)},
        options=SimpleNamespace(bound_factor=FACTOR),
        parameters=SimpleNamespace(replace_values=lambda **changed: changed[name]),
    )


def _scan(estimate: float, rise_at):
    """The test of the stand-in fit with the criterion's rise ``rise_at(value)``; also the
    values it tried, in order."""
    tried = []

    def rise(value):
        tried.append(value)
        return rise_at(value)

    return _open_end(_fit(estimate), "k_l", rise), tried


def test_the_threshold_is_half_the_95_percent_quantile_of_chi2_with_one_dof():
    # 3.841 is the quantile (3.84146) to four significant figures, within 5e-4: half of it
    # within 2.5e-4.
    assert LIKELIHOOD_RATIO_95 == pytest.approx(0.5 * chi2.ppf(0.95, 1), abs=2.5e-4)


@pytest.mark.parametrize(
    ("estimate", "direction", "values"),
    [
        (1600.0, "above", [400.0, 200.0, 100.0, 50.0, 25.0, 12.5, 6.25]),
        (6.25, "below", [25.0, 50.0, 100.0, 200.0, 400.0, 800.0, 1600.0]),
    ],
)
def test_a_flat_criterion_is_scanned_through_the_start_to_the_far_bound(
    estimate, direction, values
):
    """On the box's side the previous box's bound 100 x/÷ 16^(1/2), then steps of 16^(1/4)
    through the start to the far bound 100 x/÷ 16: every value fits as well, so the finite end
    is the far bound."""
    end, tried = _scan(estimate, lambda value: 0.0)
    assert tried == values
    assert end == OpenEnd("k_l", direction, values[0], 0.0, values[-1])
    assert end.open


def test_the_scan_stops_before_the_first_value_that_fits_worse():
    """From the lower box: rise 0 up to 200, 5 beyond; the end is 200 and 800 is not tried."""
    end, tried = _scan(6.25, lambda value: 0.0 if value <= 200.0 else 5.0)
    assert tried == [25.0, 50.0, 100.0, 200.0, 400.0]
    assert end.open and end.finite_end == 200.0


def test_a_parameter_the_data_push_onto_the_box_is_not_open_and_not_scanned():
    end, tried = _scan(1600.0, lambda value: 3.0)
    assert tried == [400.0]
    assert not end.open
    assert (end.nearer_value, end.rise, end.finite_end) == (400.0, 3.0, 400.0)


@pytest.mark.parametrize(
    ("rise", "is_open"),
    [(np.nextafter(LIKELIHOOD_RATIO_95, 0.0), True), (LIKELIHOOD_RATIO_95, False)],
)
def test_open_means_a_rise_strictly_below_the_threshold(rise, is_open):
    assert OpenEnd("k_l", "above", 400.0, float(rise), 400.0).open is is_open


@pytest.mark.parametrize(("direction", "side"), [("above", ">="), ("below", "<=")])
def test_an_open_end_states_how_far_the_parameter_fits_as_well(direction, side):
    text = OpenEnd("k_l", direction, 400.0, 0.5, 6.25).statement()
    assert text.startswith(f"k_l is not bounded {direction} by the data (k_l {side} 6.25 ")
    assert "moved back to 400 the criterion changes by 0.5, under the 1.92" in text


def test_a_closed_end_states_the_rise_that_pushes_it_onto_the_box():
    text = OpenEnd("k_l", "above", 400.0, 12.5, 400.0).statement()
    assert text == (
        "k_l: the criterion rises by 12.5 when moved back to 400 (the data push it onto the box)"
    )


def test_the_rise_is_the_fits_criterion_relative_to_its_own_value(monkeypatch):
    """``open_ends`` judges every value by the fit's criterion from the fit's initial states,
    minus the criterion at the fit itself: here 100 + (ln(p / 1600))^2 from the upper box,
    so the rise at 400 is (ln 4)^2 = 1.9218, just above the threshold 1.9205: closed."""
    fit = _fit(1600.0)
    starts = object()

    def criterion(p, given_starts):
        assert given_starts is starts
        value = 1600.0 if p is fit.parameters else p
        return 100.0 + np.log(value / 1600.0) ** 2

    monkeypatch.setattr(
        open_ended, "Criterion", SimpleNamespace(of=lambda result, recordings: criterion)
    )
    monkeypatch.setattr(open_ended, "judged_starts", lambda result: starts)
    (end,) = open_ends(fit, [], ["k_l"])
    assert end.rise == pytest.approx(np.log(4.0) ** 2, rel=1e-12)
    assert end.nearer_value == 400.0 and not end.open
