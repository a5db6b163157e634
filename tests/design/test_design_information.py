"""The predicted information is the fitter's: the same recording, fitted at the truth, gives
the same Gauss-Newton information, and the noise-model errors agree to the bootstrap's
sampling error."""

from dataclasses import replace

import numpy as np
import pytest

from hframe_id.design.calibration import misfit_factor
from hframe_id.design.excitation import Block, Layout
from hframe_id.design.information import (
    design_options,
    experiment_information,
    fitted_channel_std,
)
from hframe_id.errors import OptionError
from hframe_id.fitting import FitOptions, fit_recordings
from hframe_id.fitting.problem import default_free
from hframe_id.models import build_model
from hframe_id.recordings.sensors import SensorModel
from hframe_id.recordings.simulated import simulate_recording


@pytest.fixture(scope="module")
def inputs():
    """1 s: two doublet blocks that move both axes (x and y stay within the lasers' range)."""
    return Layout(1.0).table([Block(6.0, (2, 1)), Block(3.0, (1, 8), opposite=True)])


@pytest.fixture(scope="module")
def fitted(table, inputs):
    """The sim rig's recording of ``inputs`` fitted from the truth (converges in ~1 s)."""
    recording = simulate_recording(table, inputs, seed=1)
    return fit_recordings([recording], table, FitOptions())


@pytest.fixture(scope="module")
def predicted(table, inputs):
    return experiment_information(
        table, [inputs], design_options(default_free(build_model("hframe-8")))
    )


def test_information_is_the_fitters_gauss_newton_information(fitted, predicted):
    assert fitted.success, fitted.message
    stats = fitted.statistics
    assert predicted.names == fitted.free_names
    # The fit's textbook errors are s (F^-1)_ii^1/2 at its estimate; s ~ 1 on sim data.
    # 1 %: the estimate is off the truth by the noise (~1e-5 relative) and the data's
    # integrator differs from the transcription's (measured: within 0.25 %).
    np.testing.assert_allclose(
        predicted.relative_std(), stats.relative_std_gn / stats.noise_scale, rtol=0.01
    )


def test_noise_model_errors_agree_with_the_fits(fitted, predicted):
    stats = fitted.statistics
    ratio = predicted.noise_model_relative_std() / (stats.relative_std_noise / stats.noise_scale)
    # A bootstrap of 400 replicates has a sampling error of ~1 / sqrt(800) = 3.5 % per std,
    # and the fit's quantization errors are those of one encoder phase, the prediction's of
    # the noise-free motion: measured ratios 0.78-1.31; a factor 1.5 either way.
    assert np.all((ratio > 1 / 1.5) & (ratio < 1.5)), ratio


def test_joint_information_is_the_sum_of_the_experiments(table, inputs, predicted):
    both = experiment_information(table, [inputs, inputs[::-1]], design_options(predicted.names))
    parts = both.per_experiment()
    np.testing.assert_allclose(both.matrix, parts[0] + parts[1], rtol=1e-12)
    # The first experiment alone is the same prediction (rounding only).
    np.testing.assert_allclose(parts[0], predicted.matrix, rtol=1e-9, atol=0)


def test_laser_samples_out_of_range_carry_no_information(table):
    """A 6 V x-motion push runs past the +/-5 cm laser: those samples are left out."""
    push = np.zeros((600, 2))
    push[50:550] = (-6.0, 6.0)
    free = ("k_l", "k_r", "M_bridge", "b_bridge")
    wide = SensorModel(laser_min_m=-1.0, laser_max_m=1.0)
    narrow = experiment_information(table, [push], design_options(free))
    full = experiment_information(table, [push], design_options(free), sensors=wide)
    lasers = [narrow.output_names.index(a) for a in ("x", "y")]
    assert not narrow.valid[0][:, lasers].all() and full.valid[0][:, lasers].all()
    assert narrow.jacobian.shape[0] < full.jacobian.shape[0]
    assert np.all(np.diag(narrow.matrix) < np.diag(full.matrix))


def test_a_fit_that_estimated_its_noise_levels_lends_them_to_the_prediction(table):
    noise = {
        "weights": "estimated from the residuals",
        "channels": {
            "phi1": {"sensor_std [rad]": 5.6e-6, "weight_std [rad]": 0.0176},
            "x": {"sensor_std [m]": 5e-6, "weight_std [m]": 2.6e-4},
        },
    }
    fitted = replace(table, provenance={"noise": noise})
    assert fitted_channel_std(fitted) == {"phi1": 0.0176, "x": 2.6e-4}
    sensors = replace(table, provenance={"noise": {**noise, "weights": "sensor noise"}})
    assert fitted_channel_std(sensors) == {} and fitted_channel_std(table) == {}


def test_misfit_factor_is_the_fits_errors_over_the_predicted_ones(table, inputs, predicted):
    """A file whose reported errors are 3 x those predicted for its recordings: factor 3; one
    that reports smaller errors never shrinks the predictions (factor 1)."""
    std = predicted.predicted_relative_std() * np.abs(predicted.slopes)
    units = {p.name: p.unit for p in build_model("hframe-8").parameters}

    def reporting(factor):
        listed = {
            f"{n} [{units[n]}]": {"estimate": table.values[n], "std_error": factor * s}
            for n, s in zip(predicted.names, std, strict=True)
        }
        return replace(table, uncertainty={"parameters": listed})

    options = design_options(predicted.names)
    sensors = SensorModel()
    assert misfit_factor(reporting(3.0), [inputs], options, sensors, 1e-3) == pytest.approx(3.0)
    assert misfit_factor(reporting(0.5), [inputs], options, sensors, 1e-3) == 1.0
    with pytest.raises(OptionError, match="--calibrate"):
        misfit_factor(table, [inputs], options, sensors, 1e-3)


def test_a_rig_that_estimates_its_noise_from_the_data_is_predicted(table, inputs):
    """An imported rig may declare ``noise_std_<output>: estimate``: the prediction then
    estimates the levels from the noise-free simulated outputs, as the fit would from data,
    and the placeholder that simulates them (all zeros) is not asked to."""
    rig = {
        "backend": "imported",
        **SensorModel().as_metadata(),
        **{f"noise_std_{n}": "estimate" for n in ("phi1", "phi2", "x", "y")},
    }
    info = experiment_information(table, [inputs], design_options(("k_l", "M_cart")), rig=rig)
    assert np.all(np.isfinite(info.relative_std()))
