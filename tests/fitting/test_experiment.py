"""A recording's channels as the fit reads them (``fitting.experiment``): each channel's noise."""

import pytest
from servo_outputs import servo_model_file, servo_recording

from hframe_id.errors import FitError
from hframe_id.fitting.experiment import default_channel_std
from hframe_id.models import build_model


@pytest.fixture(scope="module")
def servo(tmp_path_factory):
    """``servo(variant)``: the model name of a DC servo variant (``servo_outputs``)."""
    folder = tmp_path_factory.mktemp("servo")
    return lambda variant: servo_model_file(folder, variant)[0]


def test_noise_comes_from_the_rig_then_the_declaration(servo):
    name = servo("shipped")
    model = build_model(name)
    declared = servo_recording(name, 4, n=200)
    assert default_channel_std(declared, "omega", model) == 0.5  # models/dc_servo.py
    assert default_channel_std(declared, "current", model) == 0.01
    rig = servo_recording(name, 4, n=200, rig={"noise_std_omega": 0.2})
    assert default_channel_std(rig, "omega", model) == 0.2  # the rig's own sensor wins
    with pytest.raises(FitError, match="noise_std in the model's Output declaration"):
        default_channel_std(declared, "omega")  # no model: nothing declares it
