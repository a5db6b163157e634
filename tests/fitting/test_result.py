"""What a fit produced (``fitting.result``): frozen results, the statements they make."""

import dataclasses
import math
from pathlib import Path

import pytest

from hframe_id.fitting.result import spread
from hframe_id.parameters import load_parameter_file

MODELS = Path(__file__).resolve().parents[2] / "models"


def test_held_parameters_and_their_prior_are_stated():
    """A fit with held table values says which, at what value and with what prior."""
    from hframe_id.fitting.consider import Consider
    from hframe_id.fitting.result import FitDiagnostics, FitResult

    def held(prior: dict) -> FitResult:
        result = FitResult.__new__(FitResult)
        object.__setattr__(result, "diagnostics", FitDiagnostics(consider=Consider(prior)))
        object.__setattr__(
            result, "parameters", load_parameter_file(MODELS / "one-axis-table2.3.yaml")
        )
        return result

    statement = held({"J_2": 0.2}).held_statement()
    assert "J_2 = 6.3e-05 (+/-20 %)" in statement and "consider covariance" in statement
    assert held({}).held_statement() is None


def test_a_result_is_frozen_and_changed_diagnostics_make_a_new_one(small_result):
    result = small_result()
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.success = False
    changed = result.with_diagnostics(at_default_box=("k_l",), residual_rms_noise_std=1.1)
    assert changed is not result and changed.diagnostics.at_default_box == ("k_l",)
    assert changed.residual_rms == 1.1
    assert result.diagnostics.at_default_box == () and math.isnan(result.residual_rms)
    assert changed.estimates is result.estimates  # the rest is the same result's


def test_spread_is_symmetric_in_log_for_log_scale_and_linear_for_signed_parameters():
    z = 1.96
    std, rel, (low, high) = spread(2.0, 0.1, False, 1.0, z)
    assert (std, rel) == pytest.approx((0.2, 0.1))
    assert (low, high) == pytest.approx((2.0 / math.exp(0.196), 2.0 * math.exp(0.196)))
    # p = p0 + s theta: a theta std of 0.1 at scale 3 is 0.3 in SI.
    std, rel, interval = spread(-1.0, 0.1, True, 3.0, z)
    assert (std, rel) == pytest.approx((0.3, 0.3))
    assert interval == pytest.approx((-1.0 - z * 0.3, -1.0 + z * 0.3))
    assert spread(0.0, 0.1, True, 3.0, z)[1] == math.inf


def test_the_status_of_a_parameter_is_worded_once_for_each_verdict(small_result):
    result = small_result()
    k_l = result.estimates["k_l"]
    assert k_l.key == "k_l [N/m]"
    assert result.status_of("k_l") == "identified"

    def status(success=True, not_identified=(), **estimate):
        estimates = {"k_l": dataclasses.replace(k_l, **estimate)}
        changed = small_result(success=success, estimates=estimates, not_identified=not_identified)
        return changed.status_of("k_l")

    assert status(success=False) == "not assessed (fit failed)"
    assert status(at_bound=True).startswith("at bound")
    assert status(open_ended="above").startswith("not bounded above by the data")
    assert status(identified=False, not_identified=("k_l",)).startswith("NOT identified")
    assert status(identified=False, relative_std=0.25) == (
        "poorly determined (relative std 25%, kept at estimate)"
    )
    assert "k_l [N/m]" in result.summary() and "identified" in result.summary()
