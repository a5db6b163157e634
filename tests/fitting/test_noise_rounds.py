"""The re-weighting rule of the noise rounds (``fitting.noise_rounds.ChannelLevels``) and the
rescaling it drives (``GaussNewton.rescale_channels``), on hand-made residuals."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from hframe_id.fitting.noise_rounds import NOISE_RTOL, ChannelLevels, channel_rms
from hframe_id.fitting.solver import GaussNewton

STD = np.array([0.01, 0.001])  # the levels in use [SI]
SENSOR = np.array([0.001, 0.0005])  # the sensors' std [SI]


def _transcription(valid: np.ndarray):
    """A stand-in with the two attributes the rule reads: weights (valid / std) per sample."""
    return SimpleNamespace(weight=valid / STD, problem=SimpleNamespace(output_names=("phi1", "x")))


def _evaluation(errors: np.ndarray, ms):
    """Weighted residuals of SI errors (W, M, n_y), with Jacobians of ones."""
    residual = errors * ms.weight
    ones = np.ones((*errors.shape, 3))
    return SimpleNamespace(
        residual=residual, jac_node=ones * ms.weight[..., None], jac_theta=ones.copy()
    )


def test_levels_within_tolerance_are_kept():
    valid = np.ones((4, 5, 2))
    ms = _transcription(valid)
    errors = np.broadcast_to(STD * (1 + 0.5 * NOISE_RTOL), valid.shape).copy()
    levels = ChannelLevels(ms, STD, SENSOR)
    assert levels(_evaluation(errors, ms)) is None
    assert np.array_equal(levels.std, STD)


def test_levels_move_to_the_residual_rms_floored_at_the_sensors():
    """phi1's errors of 0.02 (twice its level) set it to 0.02; x's of 1e-4, below its
    sensor's 5e-4, set it to the sensor's std."""
    valid = np.ones((4, 5, 2))
    valid[0, :, 1] = 0.0  # invalid samples count for nothing
    ms = _transcription(valid)
    errors = np.stack([np.full((4, 5), 0.02), np.full((4, 5), 1e-4)], axis=-1)
    levels = ChannelLevels(ms, STD, SENSOR)
    factors = levels(_evaluation(errors, ms))
    assert levels.std == pytest.approx([0.02, 0.0005], rel=1e-12)
    assert factors == pytest.approx(STD / levels.std, rel=1e-12)


def test_rescaled_residuals_are_the_errors_under_the_new_weights():
    """After ``rescale_channels`` the residuals, their Jacobians and the transcription's
    weights all say the same: errors / new std; ``channel_rms`` reads SI rms through them."""
    valid = np.ones((4, 5, 2))
    ms = _transcription(valid)
    errors = np.stack([np.full((4, 5), 0.02), np.full((4, 5), 3e-3)], axis=-1)
    ev = _evaluation(errors, ms)
    levels = ChannelLevels(ms, STD, SENSOR)
    solver = GaussNewton.__new__(GaussNewton)
    solver.ms = ms
    solver.rescale_channels(ev, levels(ev))
    assert ev.residual == pytest.approx(errors / levels.std, rel=1e-12)
    assert ev.jac_node[..., 0] == pytest.approx(1 / levels.std * np.ones_like(errors), rel=1e-12)
    assert ev.jac_theta[..., 0] == pytest.approx(STD / levels.std * np.ones_like(errors))
    rms = channel_rms(ms, ev)
    assert rms["phi1"] == pytest.approx(0.02, rel=1e-12)
    assert rms["x"] == pytest.approx(3e-3, rel=1e-12)
    assert math.isclose(float(np.max(ms.weight[..., 0])), 1 / 0.02, rel_tol=1e-12)
