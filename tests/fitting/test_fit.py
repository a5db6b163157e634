"""The fit's entry point (``fitting.fit.fit_recordings``): problems refused before solving."""

from pathlib import Path

import numpy as np
import pytest

from hframe_id.errors import FitError
from hframe_id.fitting import FitOptions, fit_recordings
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.simulated import simulate_recording

MODELS = Path(__file__).resolve().parents[2] / "models"


@pytest.fixture(scope="module")
def hframe():
    return load_parameter_file(MODELS / "hframe-8-table4.2.yaml")


@pytest.fixture(scope="module")
def recording(hframe):
    u = np.zeros((300, 2))
    u[50:250] = (-4.0, 4.0)
    return simulate_recording(hframe, u, seed=1)


def test_fit_recordings_raises_before_solving(hframe, recording):
    with pytest.raises(FitError):
        fit_recordings([], hframe)
    with pytest.raises(FitError, match="did you mean"):
        fit_recordings([recording], hframe, FitOptions(free=("tau_cm1",)))
