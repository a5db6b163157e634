"""The fit's statistics (``fitting.statistics``): which recordings carry each parameter's
information, the uncertainty estimators against white and quantization noise, and data
without information."""

from __future__ import annotations

import numpy as np
import pytest

from hframe_id.fitting.statistics import (
    Block,
    compute_statistics,
    information_shares,
    noise_model_errors,
)


def _block(label: str, rows) -> Block:
    rows = np.asarray(rows)
    return Block(label, rows, 1.0, 0.0, np.zeros(rows.size))


def test_shares_are_each_recordings_part_of_a_parameters_information():
    """Columns: one initial state (nuisance), then a and b. a is seen by recording A only;
    b by A (1^2 + 1^2 = 2) and B (2^2 + 1^2 + 1^2 = 6 over its two channels); the prior's
    row on b is not a recording's."""
    jac = np.array(
        [
            [5.0, 1.0, 1.0],  # A:phi1
            [5.0, 3.0, 1.0],  # A:phi2
            [0.0, 0.0, 2.0],  # B:phi1
            [0.0, 0.0, 1.0],  # B:phi2
            [0.0, 0.0, 1.0],  # B:phi2
            [0.0, 0.0, 9.0],  # prior on b
        ]
    )
    blocks = [
        _block("A:phi1", [0]),
        _block("A:phi2", [1]),
        _block("B:phi1", [2]),
        _block("B:phi2", [3, 4]),
        _block("prior:b", [5]),
    ]
    shares = information_shares(jac, blocks, 1, ("a", "b"))
    assert shares["a"] == pytest.approx({"A": 1.0, "B": 0.0})
    assert shares["b"] == pytest.approx({"A": 0.25, "B": 0.75})


def test_a_parameter_no_recording_sees_has_no_share():
    jac = np.zeros((2, 1))
    shares = information_shares(jac, [_block("A:x", [0]), _block("B:x", [1])], 0, ("c",))
    assert shares == {"c": {"A": 0.0, "B": 0.0}}


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


def test_statistics_of_sensitivities_too_large_to_square_do_not_raise():
    """A finite sensitivity of 1e200 overflows J^T J (a LinAlgError in the collinearity's
    elimination of the initial states): that parameter is undetermined, the others not."""
    from hframe_id.fitting.statistics import Block, compute_statistics

    rng = np.random.default_rng(1)
    jac = rng.normal(size=(200, 4))  # one initial-state column, then three parameters
    jac[:, 3] *= 1e200
    residual = rng.normal(size=200)
    block = Block("e:phi1", np.arange(200), 1.0, 0.0, np.zeros(200))
    stats = compute_statistics(jac, residual, [block], 1, ("a", "b", "c"), "robust")
    assert np.all(np.isfinite(stats.relative_std[:2]))
    assert not stats.relative_std[2] < 1e6


def test_statistics_of_a_parameter_with_almost_no_information_print_no_warning():
    """A current limit that never binds has sensitivities of ~1e-150 (dev plant 8 of issue
    25): its information, ~1e-300, inverts to an overflow. That parameter is undetermined,
    the others not, and numpy prints nothing (a RuntimeWarning on the fit's terminal)."""
    import warnings

    from hframe_id.fitting.statistics import Block, compute_statistics

    rng = np.random.default_rng(2)
    jac = rng.normal(size=(200, 3))
    # c: almost b's direction (1 - 1e-6), at 1e-150 of its size
    jac[:, 2] = (0.999999 * jac[:, 1] + 1e-6 * jac[:, 2]) * 1e-150
    residual = rng.normal(size=200)
    block = Block("e:phi1", np.arange(200), 1.0, 0.0, np.zeros(200))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        stats = compute_statistics(jac, residual, [block], 0, ("a", "b", "c"), "robust")
    assert np.isfinite(stats.relative_std[0])
    assert not stats.relative_std[2] < 1e6
