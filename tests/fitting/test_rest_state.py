"""Where a record at rest starts (``fitting.rest_state``): the belt-free motion that best fits
the position measurements, weighted by the sensors' noise, averaged over the samples that
show rest; velocities zero or a tachometer's. Measurements here are made by hand from a
belt-free pose of Table 4.2 (hframe-8: outputs phi1, phi2, x, y; two rigid modes), so the
pose they come from is known exactly."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from servo_outputs import servo_model_file, servo_recording, start

from hframe_id.fitting.dataset import REST_SAMPLES, Dataset
from hframe_id.fitting.problem import output_matrix, rigid_modes
from hframe_id.fitting.rest_state import measured_positions, measured_rates, rest_state
from hframe_id.models import build_model

#: Amplitudes of the two rigid modes of the pose measured (about 0.3 rad of motor angle).
AMPLITUDES = np.array([0.3, -0.2])


@pytest.fixture(scope="module")
def h_frame(table, recording):
    """(model, p, modes (4, 2), C (4, 4) of the positions, the step ``recording`` as a
    ``Dataset``) of hframe-8 at Table 4.2."""
    model = build_model("hframe-8")
    p = model.parameter_vector(table.values)
    c = output_matrix(model)[:, : model.n_states // 2]
    return model, p, rigid_modes(model, p), c, Dataset.from_recording(model, recording)


def _measuring(data, poses, c, at_rest=True):
    """``data`` measuring ``poses`` (N, 4) exactly (no noise), every sample valid."""
    measured = poses @ c.T
    return dataclasses.replace(
        data, measured=measured, valid=np.ones(measured.shape, dtype=bool), at_rest=at_rest
    )


def test_a_belt_free_pose_measured_exactly_is_where_the_record_starts(h_frame):
    """Up to rounding (1e-12 of poses of ~0.3 rad and ~5 mm): the pose, velocities zero."""
    model, p, modes, c, data = h_frame
    pose = modes @ AMPLITUDES
    x0 = rest_state(model, p, _measuring(data, np.tile(pose, (data.n_samples, 1)), c))
    np.testing.assert_allclose(x0, np.r_[pose, np.zeros(4)], rtol=0, atol=1e-12)


@pytest.mark.parametrize(("encoder_std", "moved"), [(None, 0.0), (1.0, 1e-3)])
def test_the_positions_follow_the_more_precise_sensors(h_frame, encoder_std, moved):
    """Lasers 1 mm off the pose the encoders show: with the encoders' noise (5.6e-6 rad, 8e-8
    m of belt at r ~ 14 mm, 65x finer than the lasers' 5 um) the cart stays within 1 um of
    the encoders' pose; with encoders of 1 rad noise it follows the lasers within 1 um. The
    belts stay unstretched either way: the positions are a rigid motion."""
    model, p, modes, c, data = h_frame
    pose = modes @ AMPLITUDES
    data = _measuring(data, np.tile(pose, (data.n_samples, 1)), c)
    measured = data.measured.copy()
    measured[:, 2:] += 1e-3  # x and y
    noise_std = data.noise_std.copy()
    if encoder_std is not None:
        noise_std[:2] = encoder_std
    data = dataclasses.replace(data, measured=measured, noise_std=noise_std)
    positions = rest_state(model, p, data)[:4]
    assert np.max(np.abs(positions[:2] - pose[:2] - moved)) < 1e-6
    np.testing.assert_allclose(modes @ (modes.T @ positions), positions, rtol=0, atol=1e-12)


@pytest.mark.parametrize("at_rest", [True, False])
def test_a_record_at_rest_starts_at_its_first_samples_mean_else_at_its_first(h_frame, at_rest):
    model, p, modes, c, data = h_frame
    amplitudes = AMPLITUDES + np.outer(np.arange(data.n_samples), [1e-3, 2e-3])
    poses = amplitudes @ modes.T
    x0 = rest_state(model, p, _measuring(data, poses, c, at_rest))
    expected = poses[:REST_SAMPLES].mean(axis=0) if at_rest else poses[0]
    np.testing.assert_allclose(x0[:4], expected, rtol=0, atol=1e-12)


def test_a_sample_with_fewer_valid_positions_than_rigid_modes_keeps_the_previous(h_frame):
    """Two rigid modes: sample 0 with none valid is at zero, sample 3 with the phi1 encoder
    alone repeats sample 2; sample 5 with the two lasers alone is placed by them."""
    model, p, modes, c, data = h_frame
    amplitudes = AMPLITUDES + np.outer(np.arange(data.n_samples), [1e-3, 2e-3])
    poses = amplitudes @ modes.T
    data = _measuring(data, poses, c)
    valid = data.valid.copy()
    valid[0] = False
    valid[3] = [True, False, False, False]
    valid[5] = [False, False, True, True]
    positions = measured_positions(model, p, dataclasses.replace(data, valid=valid))
    assert np.array_equal(positions[0], np.zeros(4))
    assert np.array_equal(positions[3], positions[2])
    np.testing.assert_allclose(positions[[1, 2, 4, 5]], poses[[1, 2, 4, 5]], rtol=0, atol=1e-12)


@pytest.mark.parametrize("at_rest", [True, False])
def test_samples_that_place_nothing_are_left_out_of_the_start(h_frame, at_rest):
    """The first three samples with no valid output (a logger starting late): at rest the
    start is the mean of samples 3-9, else sample 3's pose; not zero, nor pulled towards
    zero by the samples left out."""
    model, p, modes, c, data = h_frame
    amplitudes = AMPLITUDES + np.outer(np.arange(data.n_samples), [1e-3, 2e-3])
    poses = amplitudes @ modes.T
    data = _measuring(data, poses, c, at_rest)
    valid = data.valid.copy()
    valid[:3] = False
    data = dataclasses.replace(data, valid=valid)
    unheld = measured_positions(model, p, data, hold_missing=False)
    assert np.isnan(unheld[:3]).all() and np.isfinite(unheld[3:]).all()
    expected = poses[3:REST_SAMPLES].mean(axis=0) if at_rest else poses[3]
    np.testing.assert_allclose(rest_state(model, p, data)[:4], expected, rtol=0, atol=1e-12)


def test_a_record_whose_first_samples_place_nothing_starts_at_its_first_that_does(h_frame):
    model, p, modes, c, data = h_frame
    poses = np.tile(modes @ AMPLITUDES, (data.n_samples, 1))
    data = _measuring(data, poses, c)
    valid = data.valid.copy()
    valid[: REST_SAMPLES + 5] = False
    x0 = rest_state(model, p, dataclasses.replace(data, valid=valid))
    np.testing.assert_allclose(x0[:4], poses[0], rtol=0, atol=1e-12)


@pytest.fixture(scope="module")
def servo(tmp_path_factory):
    """(model, p, a record as a ``Dataset``) of the shipped DC servo: a tachometer (omega, a
    rate) and a current, no position output; 100 samples at rest first."""
    name, _ = servo_model_file(tmp_path_factory.mktemp("servo"), "shipped")
    model = build_model(name)
    p = model.parameter_vector(start(name).values)
    return model, p, Dataset.from_recording(model, servo_recording(name, 3, n=300))


@pytest.mark.parametrize("at_rest", [True, False])
def test_a_measured_rate_starts_at_its_measurement(servo, at_rest):
    """The tachometer's mean over its valid first samples at rest (an invalid one left out),
    its first sample's reading otherwise; the angle, which no output places, at 0."""
    model, p, data = servo
    assert data.kinds == ("rate", "other") and data.at_rest
    valid = data.valid.copy()
    valid[2, 0] = False
    data = dataclasses.replace(
        data, measured=np.where(valid, data.measured, np.nan), valid=valid, at_rest=at_rest
    )
    rates = measured_rates(model, data)
    used = valid[:, 0]
    assert np.isnan(rates[2, 0]) and np.array_equal(rates[used, 0], data.measured[used, 0])
    omega = data.measured[:REST_SAMPLES, 0]
    expected = np.nanmean(omega) if at_rest else omega[0]
    np.testing.assert_allclose(rest_state(model, p, data), [0.0, expected], rtol=1e-12, atol=0)
