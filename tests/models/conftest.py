"""Fixtures of the model tests."""

import numpy as np
import pytest

from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.simulated import simulate_recording
from hframe_id.resources import models_dir


@pytest.fixture(scope="session")
def step_recording():
    """``step_recording(volts)``: a section-4.4 x step of ``volts`` (motor 1 / motor 2 = -V /
    +V, 0.25 s of 0.4 s) simulated with Table 4.2 (the thesis's hframe-8)."""

    def record(volts: float):
        u = np.zeros((400, 2))
        u[50:300] = (-volts, volts)
        table = load_parameter_file(models_dir() / "hframe-8-table4.2.yaml")
        return simulate_recording(table, u)

    return record
