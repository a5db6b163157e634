"""Consider covariance (``fitting.consider``): what the uncertainty of held parameters does to
the fitted ones."""

import numpy as np

from hframe_id.fitting.consider import consider_covariance


def test_consider_covariance_is_the_spread_of_estimates_under_held_errors():
    """Linear least squares y = A a + C c: holding c at a wrong value moves the estimate of a
    by S dc; over many draws of dc with relative std s, cov(a) is S diag(s^2) S^T."""
    rng = np.random.default_rng(7)
    a_mat, c_mat = rng.normal(size=(200, 3)), rng.normal(size=(200, 2))
    c_mat += a_mat[:, :2] * 0.8  # held columns correlated with estimated ones
    std = np.array([0.2, 0.1])
    draws = rng.normal(size=(20000, 2)) * std
    estimates = np.linalg.lstsq(a_mat, -(draws @ c_mat.T).T, rcond=None)[0].T
    predicted = consider_covariance(a_mat, c_mat, std)
    # 20000 draws: sampling error of a covariance ~ sqrt(2 / 20000) = 1 % of its scale.
    assert np.allclose(np.cov(estimates.T), predicted, rtol=0.05, atol=0.03 * predicted.max())


def test_a_held_column_the_estimates_cannot_absorb_adds_nothing_and_a_copy_adds_its_prior():
    """S = -(J_a^T J_a)^-1 J_a^T J_c: a held column orthogonal to the estimated ones moves no
    estimate; a held column equal to estimated column 0 moves that estimate one for one
    (S = -e_0), so its variance gains the prior's sigma^2 and nothing else does."""
    a_mat = np.linalg.qr(np.random.default_rng(3).normal(size=(50, 4)))[0]
    orthogonal, estimated = a_mat[:, 3:], a_mat[:, :3]
    np.testing.assert_allclose(consider_covariance(estimated, orthogonal, [0.2]), 0, atol=1e-15)
    added = consider_covariance(estimated, estimated[:, :1] * 2.0, np.array([0.1]))
    np.testing.assert_allclose(added, np.diag([0.2**2, 0.0, 0.0]), atol=1e-14)
