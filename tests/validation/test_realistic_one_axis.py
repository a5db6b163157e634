"""The realistic one-axis pulses (an 8 A current limit the 10 V pulse reaches, stick-slip,
one sample of actuation delay, two of laser latency) fitted with a model that has the
amplifier's current limit (models/one_axis_current_limit.py, a user model) and the sensors'
latencies: a fit that the thesis's one-axis model cannot make
(docs/studies/2026-11-24-mismatch-one-axis.md)."""

from __future__ import annotations

import json

import pytest
import yaml

from hframe_id.cli import main
from hframe_id.resources import datasets_dir, models_dir

pytestmark = pytest.mark.integration

#: Sensor latencies of the realistic rig (docs/realistic-rig.md), whole samples, from the
#: actuation delay (1) and the laser's read-out (2): given, as from data sheets, not fitted.
LATENCY = ("--latency", "phi1=1", "--latency", "x=3")
#: The pulses put F_c (0.2 N in the model's file) near 0.02 N, on the default box's x/÷10
#: bound: the default fit then opens friction to zero and fits again from the start, a
#: second whole fit with its restarts (300 s of the suite on a 2-core machine, against
#: 175 s, before the all-window stages ended at the statistical resolution; 75 s since).
#: The box given at x/÷100 holds the answer inside it; the widening is tested in
#: tests/fitting/integration/test_open_ended_fits.py and test_information_share_fit.py.
BOX = ("--bound-factor", "100")


def test_the_current_limited_model_fits_the_realistic_pulses(tmp_path, capsys):
    realistic = datasets_dir() / "realistic"
    argv = [
        "fit",
        "--model-file",
        str(models_dir() / "one_axis_current_limit.py"),
        str(realistic / "5V_oneaxis.mcap"),
        str(realistic / "10V_oneaxis.mcap"),
        *LATENCY,
        *BOX,
        "--no-cross-validation",
        "--no-plots",
        "--json",
        "--out-dir",
        str(tmp_path),
    ]
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["success"] and summary["model"] == "one-axis-current-limit"
    # The model follows the pulses: residual rms measured 0.050 mrad and 0.0068 mm (0.105
    # mrad and 0.0065 mm in the default box; the thesis's one-axis model, same options: 0.29
    # rad and 5.7 mm, ended at bounds); the bounds leave room for other platforms' rounding
    # and paths, far below the plain model.
    channels = summary["channels"]
    assert channels["phi1"]["residual_rms"] < 3e-4 and channels["x"]["residual_rms"] < 2e-5
    truth = yaml.safe_load((realistic / "truth" / "one-axis.yaml").read_text())["parameters"]
    parameters = summary["parameters"]
    # Parameters the pulses determine (relative std < 10 %): inside their 95 % intervals of
    # the plant's own values (measured: k1 +4.3 %, J_1 +1.7 %, M +3.8 %; b, also
    # determined, at -9.9 %, is not asserted: in the default box it ended at -13.8 %,
    # outside its interval, the unmodelled stick-slip,
    # docs/studies/2026-11-24-mismatch-one-axis.md).
    for name, unit in (("k1", "N/m"), ("J_1", "kg m^2"), ("M", "kg")):
        low, high = parameters[name]["interval_95"]
        assert low <= truth[f"{name} [{unit}]"] <= high, name
    # The inertias within 10 % of the plant's.
    for name, unit in (("J_1", "kg m^2"), ("M", "kg")):
        assert parameters[name]["value"] == pytest.approx(truth[f"{name} [{unit}]"], rel=0.1)
