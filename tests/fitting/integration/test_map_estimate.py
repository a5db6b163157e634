"""A held parameter estimated with a prior (``FitOptions.consider_method="prior"``), fitted
whole: the maximum a posteriori estimate moves by the linear Gaussian shrinkage."""

import math
from pathlib import Path

import pytest

from hframe_id.fitting import FitOptions, fit_recordings

MODELS = Path(__file__).resolve().parents[3] / "models"


def test_the_map_estimate_moves_by_the_linear_gaussian_shrinkage(table_and_step):
    table, rec = table_and_step
    # k_b starts (the prior's mean) 30 % above the truth that made the data. In a linear
    # Gaussian model the prior moves the estimate from the data's own theta_d towards its
    # mean by C / (C + sigma^2) of the way, C the data's (marginal) variance of theta.
    start = table.replace_values(k_b=table.values["k_b"] * 1.3)
    plain = fit_recordings([rec], start, FitOptions())
    result = fit_recordings(
        [rec], start, FitOptions(consider_method="prior", consider={"k_b": 0.2})
    )
    assert result.success and result.prior_names == ("k_b",)
    assert "k_b" in result.free_names and "k_b" not in result.not_identified
    stats = plain.statistics
    j = stats.names.index("k_b")
    variance = stats.covariance_gn[j, j] / stats.noise_scale**2  # (J^T J)^-1, unscaled
    theta_data = math.log(plain.estimates["k_b"].estimate / start.values["k_b"])
    predicted = -theta_data * variance / (variance + 0.2**2)
    measured = math.log(result.estimates["k_b"].estimate / plain.estimates["k_b"].estimate)
    # Measured 1.042e-4 against 1.034e-4: the solvers stop within ~1e-6 in theta (1 % of
    # this shift), the model is not quite linear over 30 %; 5 % holds both, and a prior of
    # the wrong weight (1 / sigma instead of 1 / sigma^2 in the normal equations: x5) fails.
    assert measured == pytest.approx(predicted, rel=0.05)
    assert "Estimated with a prior" in result.held_statement()
    assert "k_b" in result.held_statement() and "with a prior" in result.summary()
