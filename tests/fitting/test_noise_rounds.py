"""The noise levels' reading of the residuals (``fitting.noise_rounds``), on hand-made
residuals: the rms of each channel in SI units, floored at its sensor's std."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from hframe_id.fitting.noise_rounds import channel_rms, noise_levels

STD = np.array([0.01, 0.001])  # the levels the transcription weighs with [SI]
SENSOR = np.array([0.001, 0.0005])  # the sensors' std [SI]


def _fit(errors: np.ndarray, valid: np.ndarray):
    """A transcription (weights valid / std) and a state whose residuals are ``errors``."""
    ms = SimpleNamespace(
        weight=valid / STD,
        problem=SimpleNamespace(output_names=("phi1", "x"), channel_std=STD),
    )
    state = SimpleNamespace(evaluation=SimpleNamespace(residual=errors * ms.weight))
    return ms, state


def test_channel_rms_is_in_si_units_over_the_valid_samples():
    valid = np.ones((4, 5, 2))
    valid[0, :, 1] = 0.0  # invalid samples count for nothing, whatever their error
    errors = np.stack([np.full((4, 5), 0.02), np.full((4, 5), 3e-3)], axis=-1)
    errors[0, :, 1] = 1.0
    ms, state = _fit(errors, valid)
    assert channel_rms(ms, state.evaluation) == pytest.approx({"phi1": 0.02, "x": 3e-3})


def test_the_next_levels_are_the_rms_floored_at_the_sensors():
    """phi1's errors of 0.02 give 0.02; x's of 1e-4, below its sensor's 5e-4, give 5e-4."""
    valid = np.ones((4, 5, 2))
    errors = np.stack([np.full((4, 5), 0.02), np.full((4, 5), 1e-4)], axis=-1)
    ms, state = _fit(errors, valid)
    assert noise_levels(ms, state, SENSOR) == pytest.approx([0.02, 5e-4], rel=1e-12)


def test_a_channel_without_valid_samples_keeps_its_level():
    valid = np.ones((4, 5, 2))
    valid[..., 1] = 0.0
    ms, state = _fit(np.full((4, 5, 2), 0.02), valid)
    assert noise_levels(ms, state, SENSOR) == pytest.approx([0.02, STD[1]], rel=1e-12)
