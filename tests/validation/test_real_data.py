"""The first real measured data: the EMPS axis (docs/real-data.md), fitted by output error on
independent 50 ms horizons with a user model, against the published IDIM-LS estimates."""

from __future__ import annotations

import json

import pytest
import yaml

from hframe_id.cli import main
from hframe_id.resources import datasets_dir, models_dir

#: Janot, Gautier, Brunot 2019: IDIM-LS on the estimation set.
PUBLISHED = {"M": 95.1089, "F_v": 203.5034, "F_c": 20.3935, "F_0": -3.1648}

pytestmark = pytest.mark.integration


def test_emps_fit_agrees_with_the_published_inverse_model(tmp_path, capsys):
    argv = [
        "fit",
        "--model-file",
        str(models_dir() / "emps_axis.py"),
        str(datasets_dir() / "real" / "emps-estimation.mcap"),
        "--json",
        "--out-dir",
        str(tmp_path),
    ]
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)  # stdout holds the JSON object only
    assert summary["success"] and summary["model"] == "emps-axis"
    parameters = summary["parameters"]
    # Two different estimators (output error on 50 ms horizons, inverse model with filtered
    # derivatives) on real data: they agree to 2.3 % here (docs/real-data.md); 5 % and 0.5 N
    # are the agreement the issue asks for, not noise-based tolerances.
    for name in ("M", "F_v", "F_c"):
        assert parameters[name]["value"] == pytest.approx(PUBLISHED[name], rel=0.05), name
        assert parameters[name]["unit"] in ("kg", "N s/m", "N") and parameters[name]["free"]
        low, high = parameters[name]["interval_95"]
        assert low < parameters[name]["value"] < high
    assert abs(parameters["F_0"]["value"] - PUBLISHED["F_0"]) < 0.5
    assert parameters["gtau"]["free"] is False and parameters["gtau"]["std"] is None
    # The parameter file names the model file, so it reads back without --model-file.
    written = yaml.safe_load(open(summary["parameter_file"]))
    assert written["model"] == "emps-axis" and written["model_file"].endswith("emps_axis.py")
    assert main(["params", "show", summary["parameter_file"]]) == 0
    # validate reads the fit (its model from model_file) and the real recording.
    capsys.readouterr()
    recording = str(datasets_dir() / "real" / "emps-estimation.mcap")
    assert main(["validate", summary["parameter_file"], recording, "--json"]) == 0
    channel = json.loads(capsys.readouterr().out)["recordings"][0]["results"][0]["channels"][0]
    # Open loop over 24.8 s the integrator drifts (docs/real-data.md): about 91 %; predicted
    # 10 samples ahead from the measured state, it follows the data.
    assert channel["name"] == "qm" and 80 < channel["simulation_fit_percent"] < 100
    assert channel["prediction_fit_percent"] > 99
    # The model cannot follow the data at the encoder's resolution: the fit says so.
    assert summary["channels"]["qm"]["residual_rms"] > 10 * 5e-8 / 12**0.5
