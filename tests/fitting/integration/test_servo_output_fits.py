"""Whole fits of outputs that are not coordinates (``Output`` declarations,
docs/custom-models.md): a DC servo's tachometer speed alone, with its angle, and with its
armature current, recovered from simulated records with known parameters; each channel's noise
estimated from the residuals; the NLP solvers refuse an output that is no state."""

from __future__ import annotations

import math

import numpy as np
import pytest
from servo_outputs import NOISE, TRUTH, servo_model_file, servo_recording, servo_run, start

from hframe_id.errors import OptionError
from hframe_id.fitting import FitOptions, fit_recordings
from hframe_id.fitting.dataset import REST_SAMPLES


@pytest.fixture(scope="module")
def servo(tmp_path_factory):
    """``servo(variant)``: the model name of a DC servo variant (``servo_outputs``)."""
    folder = tmp_path_factory.mktemp("servo")
    return lambda variant: servo_model_file(folder, variant)[0]


def _check_recovered(result, limits: dict[str, float]) -> None:
    """Each estimate within its relative limit of the truth and within 4 of its own standard
    errors (seeded data: a correct fit misses 4 sigma with probability 6e-5)."""
    assert result.success, result.message
    for name, limit in limits.items():
        est = result.estimates[name]
        error = est.estimate - TRUTH[name]
        assert abs(error) <= limit * TRUTH[name], (name, est.estimate, TRUTH[name])
        assert abs(error) <= 4 * est.std_error, (name, est.estimate, est.std_error)


@pytest.mark.parametrize("variant", ["speed", "angle-speed"])
def test_a_tachometer_speed_alone_or_with_the_angle_recovers_the_rotor(servo, variant):
    name = servo(variant)
    # From the speed, J w' = K g V / R - (K^2 / R + B) w - tau_c fixes J / g, B / g and
    # tau_c / g: the amplifier gain is held at its (known) value, J, B and tau_c are fitted
    # from the catalogue's start (30-50 % off).
    result = fit_recordings(
        [servo_recording(name, 1)], start(name, g=TRUTH["g"]), FitOptions(verbose=0, fix=("g",))
    )
    # 2000 samples at 0.5 rad/s tachometer noise: measured errors +0.016 % (J), -0.27 % (B),
    # +0.42 % (tau_c) with the speed alone, standard errors 0.01 %, 0.43 %, 0.43 %; below
    # 0.002 % with the angle (4096 counts/rev). The limits are 7-50 standard errors of the
    # speed-only fit and far above the solver's step tolerance (1e-6 relative): they test
    # the output map, not the noise draw.
    _check_recovered(result, {"J": 0.005, "B": 0.05, "tau_c": 0.03})


def test_speed_and_armature_current_recover_the_gain_too(servo):
    # The shipped model: the current (g V - K w) / R, nonlinear in the parameters, adds
    # g / R, so the gain is fitted with J, B and tau_c (K and R held, the data sheet's).
    name = servo("shipped")
    result = fit_recordings([servo_recording(name, 2)], start(name), FitOptions(verbose=0))
    # Measured errors: -0.007 % (J), +0.03 % (B), -0.47 % (tau_c), -0.005 % (g), standard
    # errors 0.011 %, 0.45 %, 0.49 %, 0.007 %; limits as above.
    _check_recovered(result, {"J": 0.005, "B": 0.05, "tau_c": 0.03, "g": 0.005})


def test_the_nlp_solvers_refuse_an_output_that_is_no_state(servo):
    name = servo("shipped")
    with pytest.raises(OptionError, match="outputs current: use the Gauss-Newton solver"):
        fit_recordings(
            [servo_recording(name, 2, n=300)], start(name), FitOptions(verbose=0, solver="ipopt")
        )


def test_the_residuals_estimate_each_channels_noise(servo):
    name = servo("angle-speed")
    result = fit_recordings(
        [servo_recording(name, 5)],
        start(name, g=TRUTH["g"]),
        FitOptions(verbose=0, fix=("g",), noise="estimate"),
    )
    assert result.success, result.message
    channels = result.diagnostics.noise.channels
    # The record starts from the replay's rest state (``fitting.replayed_rest``): the angle
    # at the mean of its first REST_SAMPLES readings, off the true rest angle by their mean
    # noise d, which every later angle residual keeps (nothing pulls a rotor back), so its
    # rms is sqrt(std^2 + d^2); the speed starts at 0, exactly.
    rec = servo_recording(name, 5)
    _, _, clean = servo_run(name, 5, rec.outputs.shape[0])
    theta = list(rec.output_names).index("theta")
    offset = float(np.mean((rec.outputs - clean)[:REST_SAMPLES, theta]))
    expected = {"theta": math.hypot(NOISE["theta"], offset), "omega": NOISE["omega"]}
    # The rms of 2000 residuals estimates each noise std within 2 sqrt(1 / (2 N)) = 3 %.
    for output in ("theta", "omega"):
        assert channels[output].residual_rms == pytest.approx(expected[output], rel=0.03)
