"""The Dataset: a recording on a model's channels, read once by fitting and validation."""

import dataclasses
import math

import numpy as np
import pytest
from servo_outputs import servo_model_file

from hframe_id.errors import FitError
from hframe_id.fitting import FitOptions
from hframe_id.fitting.dataset import Dataset, output_kinds, starts_at_rest
from hframe_id.fitting.problem import build_problem
from hframe_id.models import build_model
from hframe_id.recordings.sensors import SensorModel
from hframe_id.validation.replay import channels


@pytest.fixture(scope="module")
def model():
    return build_model("hframe-8")


@pytest.fixture(scope="module")
def servo(tmp_path_factory):
    """``servo(variant)``: the model name of a DC servo variant (``servo_outputs``)."""
    folder = tmp_path_factory.mktemp("servo")
    return lambda variant: servo_model_file(folder, variant)[0]


@pytest.fixture(scope="module")
def step(table, x_step):
    """A 4 V x-motion step from rest (50 samples of pre-roll), one laser sample invalid."""
    recording = x_step(table, seed=7)
    valid = recording.valid.copy()
    valid[120, 2] = False
    return dataclasses.replace(recording, valid=valid)


def test_a_recording_on_the_models_channels(model, step):
    data = Dataset.from_recording(model, step)
    assert data.name == step.name() and data.recording is step
    assert data.names == ("phi1", "phi2", "x", "y")
    assert data.units == ("rad", "rad", "m", "m")
    assert data.kinds == ("position",) * 4
    assert data.input_names == ("u1", "u2")
    assert data.n_samples == step.n_samples == data.measured.shape[0]
    assert data.sample_period_s == 1e-3


def test_invalid_samples_are_nan_and_not_valid(model, step):
    data = Dataset.from_recording(model, step)
    assert not data.valid[120, 2] and math.isnan(data.measured[120, 2])
    assert np.array_equal(np.isnan(data.measured), ~data.valid)
    assert np.array_equal(data.measured[data.valid], step.outputs[step.valid])


def test_columns_follow_the_model_not_the_file(model, step):
    order = [3, 1, 0, 2]
    shuffled = dataclasses.replace(
        step,
        outputs=step.outputs[:, order],
        valid=step.valid[:, order],
        output_names=tuple(step.output_names[j] for j in order),
    )
    a, b = Dataset.from_recording(model, step), Dataset.from_recording(model, shuffled)
    assert b.names == a.names
    assert np.array_equal(b.measured, a.measured, equal_nan=True)
    assert np.array_equal(b.valid, a.valid)


def test_inputs_are_the_voltages_after_the_dac(model, step):
    data = Dataset.from_recording(model, step)
    dac = SensorModel(dac_bits=12, dac_min_v=-10.0, dac_max_v=10.0)  # the sim rig's
    assert np.array_equal(data.inputs, dac.dac(step.inputs))
    assert not np.array_equal(data.inputs, step.inputs)  # 4 V is not a 12-bit code


def test_noise_std_is_each_sensors(model, step):
    data = Dataset.from_recording(model, step)
    encoder = 2 * math.pi / step.rig["encoder_counts_per_rev"] / math.sqrt(12)
    laser = step.rig["laser_noise_std_m"]
    assert data.noise_std.tolist() == [encoder, encoder, laser, laser]


def test_what_is_known_of_the_initial_state(model, step, in_motion):
    assert Dataset.from_recording(model, step).at_rest
    moving = Dataset.from_recording(model, in_motion(step))
    assert not moving.at_rest
    # A noise 1e4 times the sensors' hides the motion: rest cannot be told from it.
    assert moving.shows_rest(moving.noise_std * 1e4)


def test_delayed_advances_a_channel(model, step):
    data = Dataset.from_recording(model, step)
    assert data.delayed({}) is data and data.delayed({"phi1": 0}) is data
    late = data.delayed({"x": 3})
    assert np.array_equal(late.measured[:-3, 2], data.measured[3:, 2], equal_nan=True)
    assert not late.valid[-3:, 2].any() and np.isnan(late.measured[-3:, 2]).all()
    assert not late.valid[117, 2]  # the invalid sample 120 moved with its channel
    for j in (0, 1, 3):
        assert np.array_equal(late.measured[:, j], data.measured[:, j], equal_nan=True)
    assert np.array_equal(data.valid[-3:, 2], step.valid[-3:, 2])  # the original unchanged


def test_a_dataset_is_frozen(model, step):
    data = Dataset.from_recording(model, step)
    with pytest.raises(dataclasses.FrozenInstanceError):
        data.at_rest = False


def test_recordings_not_on_the_models_channels_are_refused(model, step):
    with pytest.raises(FitError, match="inputs"):
        Dataset.from_recording(model, dataclasses.replace(step, input_names=("u2", "u1")))
    with pytest.raises(FitError, match="no output 'y'"):
        Dataset.from_recording(
            model,
            dataclasses.replace(
                step,
                outputs=step.outputs[:, :3],
                valid=step.valid[:, :3],
                output_names=step.output_names[:3],
            ),
        )
    inputs = step.inputs.copy()
    inputs[10, 0] = np.nan
    no_dac = {k: v for k, v in step.rig.items() if k != "dac_bits"}  # inputs as commanded
    with pytest.raises(FitError, match="non-finite"):
        Dataset.from_recording(model, dataclasses.replace(step, inputs=inputs, rig=no_dac))
    rig = {k: v for k, v in step.rig.items() if k != "laser_noise_std_m"}
    with pytest.raises(FitError, match="laser_noise_std_m"):
        Dataset.from_recording(model, dataclasses.replace(step, rig=rig))


def test_fitting_and_validation_read_the_same_dataset(model, table, step):
    """The fitter's experiments and the replay's channels are the recording's Dataset."""
    data = Dataset.from_recording(model, step)
    experiment = build_problem([step], table, FitOptions(free=("k_l",))).experiments[0]
    replayed = channels(model, step)
    for other in (experiment, replayed):
        assert isinstance(other, Dataset)
        assert np.array_equal(other.measured, data.measured, equal_nan=True)
        assert np.array_equal(other.inputs, data.inputs)
        assert np.array_equal(other.noise_std, data.noise_std)
        assert other.at_rest == data.at_rest


def test_a_speed_shows_rest_by_its_value(servo):
    model = build_model(servo("shipped"))
    assert output_kinds(model) == ("rate", "other")
    dt, std = 1e-3, np.array([0.5])
    valid = np.ones((10, 1), dtype=bool)
    still = np.random.default_rng(6).normal(0.0, 0.5, (10, 1))
    turning = still + 100.0  # a constant 100 rad/s: no slope, but not at rest
    assert starts_at_rest(still, valid, std, 10, dt, ("rate",))
    assert not starts_at_rest(turning, valid, std, 10, dt, ("rate",))
    assert starts_at_rest(turning, valid, std, 10, dt)  # read as a position, it is still
    # A current alone cannot tell rest from motion: rest is not assumed.
    assert not starts_at_rest(still, valid, std, 10, dt, ("other",))
