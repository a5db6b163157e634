"""The fit report (``fitting.report``): the truth it compares with, and an import without side
effects."""

import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from hframe_id.fitting.report import comparable_truth
from hframe_id.parameters import load_parameter_file
from hframe_id.parameters.reduce import reduce_to_hframe8

MODELS = Path(__file__).resolve().parents[2] / "models"
REDUCED_LABEL = "truth (section-4.1 reduction of the plant)"


@pytest.fixture(scope="module")
def h20_plant():
    return load_parameter_file(MODELS / "hframe-20-table3.1.yaml")


def test_truth_of_another_variant_is_reduced_or_skipped_with_a_note(h20_plant):
    recordings = [SimpleNamespace(truth=h20_plant), SimpleNamespace(truth=h20_plant)]
    truth, label, note = comparable_truth(recordings, "hframe-8")
    assert truth.variant == "hframe-8" and label == REDUCED_LABEL
    assert truth.values == reduce_to_hframe8(h20_plant).values
    assert "section-4.1 reduction" in note
    truth, label, note = comparable_truth(recordings, "hframe-20")
    assert truth is h20_plant and label == "truth"
    truth, label, note = comparable_truth(recordings, "one-axis")
    assert truth is None and note.startswith("No truth column") and "hframe-20" in note
    # recordings of different plants: no common truth, nothing to say
    other = h20_plant.replace_values(k_1=1.1 * h20_plant.values["k_1"])
    assert comparable_truth([recordings[0], SimpleNamespace(truth=other)], "hframe-8")[0] is None


@pytest.mark.parametrize("module", ["hframe_id.fitting.report", "hframe_id.fleet.report"])
def test_importing_a_report_sets_no_matplotlib_backend(module):
    """No import-time side effects: the backend of a program that imports a report module is
    its own (pyplot is never imported; the figures are drawn on Agg canvases when saved)."""
    code = (
        # The raw rcParams entry: matplotlib.get_backend() would itself import pyplot.
        "import sys, matplotlib; raw = lambda: dict.__getitem__(matplotlib.rcParams, 'backend'); "
        f"before = raw(); import {module}; "
        "print('matplotlib.pyplot' in sys.modules, raw() == before)"
    )
    env = {k: v for k, v in os.environ.items() if k != "MPLBACKEND"}
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env
    )
    assert done.stdout.split() == ["False", "True"]
