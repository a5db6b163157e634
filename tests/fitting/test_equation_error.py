"""The equation-error start (``fitting.equation_error``): it lands near the truth, and its
Savitzky-Golay derivatives and zero-padded convolution are SciPy's bit for bit."""

from pathlib import Path

import numpy as np
import pytest

from hframe_id.fitting import FitOptions
from hframe_id.fitting.equation_error import (
    _robust_gauss_newton,
    convolve_zero_padded,
    equation_error_start,
    savgol_derivative,
)
from hframe_id.fitting.problem import build_problem
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.simulated import simulate_recording

MODELS = Path(__file__).resolve().parents[2] / "models"


def test_equation_error_start_lands_near_the_truth():
    truth = load_parameter_file(MODELS / "hframe-8-table4.2.yaml")
    recs = []
    for i, volts in enumerate([(-4.0, -4.0), (-4.0, 4.0)]):
        u = np.zeros((700, 2))
        u[50:550] = volts
        recs.append(simulate_recording(truth, u, seed=10 + i))
    # Start a factor 2 off; the regression must come back to within 30 % (it is biased by
    # differentiation and smoothing; its job is the basin, not the answer).
    start = truth.replace_values(
        **{n: truth.values[n] * (2.0 if i % 2 else 0.5)
           for i, n in enumerate(build_problem(recs, truth, FitOptions()).free_names)}
    )  # fmt: skip
    problem = build_problem(recs, start, FitOptions())
    ms = MultipleShooting(problem)
    ms.initial_nodes(problem.p_initial)
    theta = equation_error_start(problem, ms.measured_positions, ms.measured_usable)
    p = problem.parameters(theta)
    pairs = zip(problem.free, problem.free_names, strict=True)
    errors = {n: p[i] / truth.values[n] - 1 for i, n in pairs}
    for name in ("k_l", "k_r", "k_b", "J_M1", "J_M2", "M_bridge", "M_cart", "tau_cM1", "g_2"):
        assert abs(errors[name]) < 0.3, (name, errors[name])


@pytest.mark.parametrize("window", [5, 11])
@pytest.mark.parametrize("deriv", [1, 2])
def test_savitzky_golay_derivative_is_scipy_bit_for_bit_in_the_interior(window, deriv):
    """Bitwise, not within a tolerance: the equation-error start feeds a fit whose path can
    turn on the last bit (a 1e-14 change of these derivatives was measured to move the
    identifiability test's fit to another stall)."""
    from scipy.signal import savgol_filter

    y = np.cumsum(np.random.default_rng(0).normal(size=2000)) * 1e-3
    half = window // 2
    expected = savgol_filter(y, window, 3, deriv=deriv, delta=1e-3)[half:-half]
    np.testing.assert_array_equal(
        savgol_derivative(y, window, 3, deriv, 1e-3)[half:-half], expected
    )


@pytest.mark.parametrize(
    "weights",
    [[0.1, 0.3, 0.7, 0.3, 0.1], [0.3, -0.7, 0.0, 0.7, -0.3], [0.3, -1.2, 2.5, 0.7, -0.1]],
    ids=["symmetric", "antisymmetric", "general"],
)
def test_zero_padded_convolution_is_scipy_bit_for_bit(weights):
    """Each of the C loop's three paths (the weights' symmetry decides), on a rough signal
    whose sums round differently in another order: a loop that always took the general path,
    or numpy.convolve, differs from SciPy in the last bits on the first two."""
    from scipy.ndimage import convolve1d

    y = np.cumsum(np.random.default_rng(1).normal(size=500)) * 1e3
    np.testing.assert_array_equal(
        convolve_zero_padded(y, np.array(weights)), convolve1d(y, weights, mode="constant")
    )


def test_savitzky_golay_derivatives_of_a_cubic_are_exact_in_the_interior():
    """Order 3 fits a cubic exactly over every window: its first and second derivatives come
    out exact (to rounding: the weights ~1/dt^2 = 1e6 times values of order 1)."""
    dt = 1e-3
    t = np.arange(200) * dt
    y = t**3 - 2 * t**2 + t
    for window in (5, 11):
        half = window // 2
        inner = slice(half, -half)
        first = savgol_derivative(y, window, 3, 1, dt)[inner]
        second = savgol_derivative(y, window, 3, 2, dt)[inner]
        np.testing.assert_allclose(first, (3 * t**2 - 4 * t + 1)[inner], rtol=0, atol=1e-9)
        np.testing.assert_allclose(second, (6 * t - 4)[inner], rtol=0, atol=1e-5)


def test_the_robust_regression_recovers_exact_parameters_of_a_linear_model():
    """Noise-free data of a model linear in its parameters (residual A theta - b, b = A
    theta_true): the reweighted Levenberg-Marquardt lands on theta_true. It stops on a step
    below 1e-6 with its damping already down to <= 1e-4 of the curvature, so what is left is
    far below that step; 1e-7 tests it."""
    rng = np.random.default_rng(2)
    a_mat = rng.normal(size=(300, 4))
    truth = np.array([0.4, -0.7, 1.2, 0.05])
    b = a_mat @ truth

    def residual(theta):
        return a_mat @ theta - b, a_mat

    bounds = np.full(4, -5.0), np.full(4, 5.0)
    theta = _robust_gauss_newton(residual, np.zeros(4), *bounds)
    np.testing.assert_allclose(theta, truth, rtol=0, atol=1e-7)
    # A bound below the truth stops that parameter there (the box is respected).
    upper = np.array([5.0, 5.0, 1.0, 5.0])
    assert _robust_gauss_newton(residual, np.zeros(4), bounds[0], upper)[2] <= 1.0
