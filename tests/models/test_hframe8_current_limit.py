"""hframe-8-current-limit: hframe-8 with current-limited amplifiers (built in,
``hframe_id.models.hframe8.CURRENT_LIMITED``)."""

import numpy as np

from hframe_id.parameters import load_parameter_file
from hframe_id.resources import models_dir
from hframe_id.validation.replay import simulate_channels


def test_without_a_binding_limit_the_model_is_hframe8(step_recording):
    """I_max = 1e6 A: the simulation of a 6 V step is hframe-8's to 1e-12 of each channel's
    range (measured: 2e-13 on y, the smallest channel, 4e-16 to 6e-16 on the others)."""
    limited = load_parameter_file(models_dir() / "hframe-8-current-limit.yaml")
    plain = load_parameter_file(models_dir() / "hframe-8-table4.2.yaml")
    assert limited.variant == "hframe-8-current-limit"
    assert {k: v for k, v in limited.values.items() if k != "I_max"} == plain.values
    recording = step_recording(6.0)
    _, expected = simulate_channels(plain, recording)
    _, actual = simulate_channels(limited.replace_values(I_max=1e6), recording)
    scale = np.abs(expected).max(axis=0)
    assert np.all(scale > 0)
    assert np.all(np.abs(actual - expected).max(axis=0) / scale < 1e-12)


def test_the_8_A_limit_slows_a_6_V_step_but_not_a_2_V_one(step_recording):
    """At 0.71 ohm 8 A binds from about 5.7 V: the 6 V step moves less far (measured: 4 %
    at the end of the step), the 2 V step (2.8 A, where the limit's correction is 1e-20 A)
    is hframe-8's to rounding (measured 2e-15 of the largest output)."""
    limited = load_parameter_file(models_dir() / "hframe-8-current-limit.yaml")
    plain = load_parameter_file(models_dir() / "hframe-8-table4.2.yaml")
    x = 2  # output order phi1, phi2, x, y
    _, fast = simulate_channels(plain, step_recording(6.0))
    _, slow = simulate_channels(limited, step_recording(6.0))
    assert abs(slow[299, x]) < 0.99 * abs(fast[299, x])
    _, small_plain = simulate_channels(plain, step_recording(2.0))
    _, small_limited = simulate_channels(limited, step_recording(2.0))
    assert np.abs(small_limited - small_plain).max() <= 1e-12 * np.abs(small_plain).max()
