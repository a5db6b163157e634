"""Shared fixtures of the fitting tests."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.simulated import simulate_recording

MODELS = Path(__file__).resolve().parents[2] / "models"


@pytest.fixture(scope="module")
def table():
    """Table 4.2 (hframe-8), the default start."""
    return load_parameter_file(MODELS / "hframe-8-table4.2.yaml")


def _x_step(params, seed: int, volts: float = 4.0):
    u = np.zeros((400, 2))
    u[50:350] = (-volts, volts)
    return simulate_recording(params, u, seed=seed)


@pytest.fixture(scope="session")
def x_step():
    """``x_step(params, seed, volts=4.0)``: a 0.4 s x-motion step of ``params`` from rest (50
    samples of pre-roll) recorded by the sim rig's sensors."""
    return _x_step


@pytest.fixture(scope="module")
def truth(table):
    """Table 4.2 with k_l, M_cart and F_c_cart moved (-5 %, +10 %, -25 %): a plant the start
    is near but not at."""
    return table.replace_values(k_l=12500.0, M_cart=1.15, F_c_cart=0.3)


@pytest.fixture(scope="module")
def steps(truth, x_step):
    """Two 0.4 s x-motion steps (+4 V and -4 V) of ``truth`` from rest."""
    return [x_step(truth, seed=3), x_step(truth, seed=4, volts=-4.0)]


@pytest.fixture(scope="session")
def in_motion():
    """``in_motion(recording, first)``: the recording from sample ``first`` on, a record that
    starts in motion (its time from 0)."""

    def cut(recording, first: int = 150):
        return dataclasses.replace(
            recording,
            time_s=recording.time_s[first:] - recording.time_s[first],
            inputs=recording.inputs[first:],
            outputs=recording.outputs[first:],
            valid=recording.valid[first:],
        )

    return cut
