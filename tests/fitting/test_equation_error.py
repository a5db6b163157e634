"""The fitter's numerical building blocks: compiled sensitivities, window integration, the
condensed Jacobian, the equation-error start and the uncertainty estimators."""

from pathlib import Path

import numpy as np
import pytest

from hframe_id.fitting import FitOptions
from hframe_id.fitting.equation_error import (
    convolve_zero_padded,
    equation_error_start,
    savgol_derivative,
)
from hframe_id.fitting.problem import build_problem
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.fitting.solver import GaussNewton
from hframe_id.fitting.statistics import Block, compute_statistics, noise_model_errors
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.simulated import simulate_recording
from hframe_id.simulation.open_loop import simulate

MODELS = Path(__file__).resolve().parents[2] / "models"


@pytest.fixture(scope="module")
def setup():
    truth = load_parameter_file(MODELS / "hframe-8-table4.2.yaml")
    u = np.zeros((400, 2))
    u[50:300] = (-4.0, 2.0)
    rec = simulate_recording(truth, u, seed=4)
    problem = build_problem([rec], truth, FitOptions())
    ms = MultipleShooting(problem).uniform()
    p = problem.p_initial
    n_sub = ms.substep_plan(p, problem.smoothing)["stiff"]
    states = simulate(ms.model, p, problem.experiments[0].inputs, 1e-3, n_substeps=n_sub)
    nodes = states[ms.window_start]
    return problem, ms, nodes, states


def test_windows_reproduce_the_simulator(setup):
    problem, ms, nodes, states = setup
    ev = ms.evaluate(nodes, np.zeros(len(problem.free)), problem.smoothing)
    # Same RK4, same substeps: the window ends are the next nodes to rounding.
    assert np.max(np.abs(ev.x_end[:-1] - nodes[1:])) < 1e-10
    assert np.max(np.abs(ms.defects(ev, nodes))) < 1e-3  # in noise units


def test_sensitivities_match_finite_differences(setup):
    problem, ms, nodes, _ = setup
    theta = np.zeros(len(problem.free))
    ev = ms.evaluate(nodes, theta, problem.smoothing)
    w = 12  # a window in motion
    for j in (0, 3, 5, 11, 15):  # k_l, J_M1, M_cart, tau_cM1 (Coulomb), g_2
        h = 1e-6
        plus = theta.copy()
        plus[j] += h
        minus = theta.copy()
        minus[j] -= h
        end_p = ms.evaluate(nodes, plus, problem.smoothing).x_end[w]
        end_m = ms.evaluate(nodes, minus, problem.smoothing).x_end[w]
        fd = (end_p - end_m) / (2 * h)
        exact = ev.b_end[w, :, j]
        # Central differences are good to ~1e-6 relative of the largest entry here.
        assert np.max(np.abs(fd - exact)) <= 1e-5 * np.max(np.abs(exact)) + 1e-12, j
    for i in (0, 2, 4, 6):
        h = 1e-7
        plus, minus = nodes.copy(), nodes.copy()
        plus[w, i] += h
        minus[w, i] -= h
        fd = (
            ms.evaluate(plus, theta, problem.smoothing).x_end[w]
            - ms.evaluate(minus, theta, problem.smoothing).x_end[w]
        ) / (2 * h)
        assert np.max(np.abs(fd - ev.a_end[w, :, i])) <= 1e-5 * np.max(np.abs(fd)) + 1e-9, i


def test_condensed_jacobian_is_the_single_shooting_jacobian(setup):
    problem, ms, nodes, _ = setup
    theta = np.zeros(len(problem.free))
    ev = ms.evaluate(nodes, theta, problem.smoothing)
    gn = GaussNewton(ms)
    jac, residual, blocks = gn.condensed_jacobian(ev, nodes, np.ones(len(problem.free), bool))
    j = problem.free_names.index("k_b")
    h = 1e-6
    outs = []
    for sign in (1, -1):
        th = theta.copy()
        th[j] += sign * h
        p = problem.parameters(th)
        x = simulate(ms.model, p, problem.experiments[0].inputs, 1e-3, x0=nodes[0],
                     n_substeps=ev.n_substeps[1])[:-1]  # fmt: skip
        outs.append(x @ ms.c.T / problem.channel_std)
    fd = (outs[0] - outs[1]) / (2 * h)
    valid = problem.experiments[0].valid
    column = jac[:, ms.n_nuisance + j]  # after the estimated initial states (none at rest)
    # Rows are (window, sample, channel) of the valid samples, i.e. time-major order.
    assert column == pytest.approx(fd[valid], rel=1e-4, abs=1e-3 * np.max(np.abs(fd)))
    assert sum(b.rows.size for b in blocks) == residual.size


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


def _linear_problem(noise: str, seed: int):
    """y = a + b t observed with white or 'quantized' noise; returns J, r, blocks, truth."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, 2000)
    jac = np.column_stack([np.ones_like(t), t])
    step = 1.0
    slow = 3.0 * t  # crosses only 3 quantization levels: long plateaus
    if noise == "white":
        err = rng.standard_normal(t.size) / np.sqrt(12)
    else:
        u = rng.uniform()
        err = (np.floor(slow / step + u) - np.floor(u)) * step - slow
    sigma = step / np.sqrt(12)
    y = slow + err
    beta = np.linalg.lstsq(jac / sigma, y / sigma, rcond=None)[0]
    residual = (jac @ beta - y) / sigma
    block = Block("x", np.arange(t.size), sigma, step if noise != "white" else 0.0, y)
    return jac / sigma, residual, [block], beta - np.array([0.0, 3.0])


def test_textbook_errors_are_right_for_white_noise_and_wrong_for_quantization():
    z_white, z_quant_gn, z_quant_noise = [], [], []
    for seed in range(40):
        jac, r, blocks, err = _linear_problem("white", seed)
        st = compute_statistics(jac, r, blocks, 0, ("a", "b"), "gauss-newton")
        z_white.append(err / st.relative_std)
        jac, r, blocks, err = _linear_problem("quantized", seed)
        st = compute_statistics(jac, r, blocks, 0, ("a", "b"), "noise-model")
        z_quant_gn.append(err / st.relative_std_gn)
        z_quant_noise.append(err / st.relative_std_noise)
    rms = lambda z: float(np.sqrt(np.mean(np.square(z))))  # noqa: E731
    # 80 z-scores: rms within ~+/-25 % of 1 when calibrated.
    assert 0.75 < rms(z_white) < 1.25
    assert rms(z_quant_gn) > 3  # plateaus make textbook errors far too small
    assert 0.6 < rms(z_quant_noise) < 1.4


def test_noise_model_errors_reproduce_quantization():
    rng = np.random.default_rng(0)
    measured = np.linspace(0, 10, 1001)
    block = Block("enc", np.arange(1001), 1.0 / np.sqrt(12), 1.0, measured)
    errors = noise_model_errors([block], np.zeros(1001), rng, 50)
    # Errors of a quantizer in sigma units: within [-sqrt(12), sqrt(12)], std 1, and constant
    # while the signal stays within one count.
    assert np.all(np.abs(errors) <= np.sqrt(12) + 1e-9)
    # Each replicate: a constant offset (the power-up phase, absorbed by the initial state
    # in a fit) plus an error of std 1 (uniform quantization).
    assert np.std(errors - errors.mean(axis=0), axis=0) == pytest.approx(1.0, abs=0.05)
    assert np.std(errors.mean(axis=0)) == pytest.approx(1.0, abs=0.3)


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


def test_statistics_of_data_without_information_do_not_raise():
    """A plant that never moves (friction above the motors' stall torque) gave overflowing,
    then NaN sensitivities and a LinAlgError: now every parameter is simply undetermined."""
    from hframe_id.fitting.statistics import Block, compute_statistics

    rng = np.random.default_rng(0)
    jac = rng.normal(size=(200, 3))
    jac[:, 1] = 0.0  # a parameter the data do not see
    jac[5, 2] = np.inf
    jac[7, 2] = np.nan
    residual = rng.normal(size=200)
    block = Block("e:phi1", np.arange(200), 1.0, 0.0, np.zeros(200))
    stats = compute_statistics(jac, residual, [block], 0, ("a", "b", "c"), "robust")
    assert np.isfinite(stats.relative_std[0])
    assert not stats.relative_std[1] < 1e6  # undetermined: huge or infinite
    assert np.isinf(stats.collinearity[1])
