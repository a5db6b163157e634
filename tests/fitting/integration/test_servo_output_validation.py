"""Validation of outputs that are not coordinates, and the issue's servo scenario end to end: a
servo's N x 7 ``data`` matrices imported with column syntax, the speed column fitted as the
output of a declared rotor model, validated on a held-out file (issue 28, item 3)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.io
from servo_outputs import (
    NOISE,
    SAMPLE_PERIOD_S,
    TRUTH,
    servo_model_file,
    servo_recording,
    servo_run,
)

from hframe_id.cli import main
from hframe_id.control import declare_controller
from hframe_id.errors import ControllerError
from hframe_id.models import Signal
from hframe_id.parameters import ParameterSet, load_parameter_file, save_parameter_file
from hframe_id.validation import ValidationOptions, validate


def test_validate_scores_a_speed_and_a_current_in_their_units(tmp_path):
    name, _ = servo_model_file(tmp_path, "shipped")
    truth = ParameterSet(name, dict(TRUTH), "truth", "test")
    result = validate([truth], [servo_recording(name, 7)])
    channels = {c.name: c for c in result.recordings[0].runs[0].channels}
    assert [(c.name, c.unit) for c in channels.values()] == [("omega", "rad/s"), ("current", "A")]
    for output, channel in channels.items():
        # The truth replayed from rest: its residual is the added noise, whose rms over 2000
        # samples is within 3 sqrt(1 / (2 N)) = 5 % of its std; the signals swing ~100x
        # their noise, so the fit % is above 99.
        assert channel.residual_rms == pytest.approx(NOISE[output], rel=0.05), output
        assert channel.simulation_fit_percent > 99.0, output
        assert channel.prediction_fit_percent > 99.0, output


def test_a_closed_loop_refuses_outputs_of_the_inputs_in_one_line(tmp_path):
    name, _ = servo_model_file(tmp_path, "shipped")
    speed_loop = declare_controller(
        name="speed-loop",
        description="proportional speed loop (test)",
        commands=[Signal("V", "V", "amplifier input")],
        measured=["omega"],
        law=lambda y, r, z, g, T: {"commands": {"V": 0.1 * (100.0 - y["omega"])}},
    )
    truth = ParameterSet(name, dict(TRUTH), "truth", "test")
    options = ValidationOptions(controller=speed_loop)
    # The loop would read y = h(x) before computing the input h needs (the current).
    with pytest.raises(ControllerError, match="output that depends on its inputs") as err:
        validate([truth], [servo_recording(name, 8, n=200)], options)
    assert "\n" not in str(err.value)


def _servo_matrix(path, name: str, seed: int) -> None:
    """A servo's identification file as MATLAB saves it: ``data`` N x 7 (time [s], amplifier
    input [V], angle [rad], speed [rpm], current [A], reference [V], enable flag) and a
    scalar sampling rate ``fs`` [Hz] (rig metadata)."""
    u, states, _ = servo_run(name, seed)
    rng = np.random.default_rng(2000 + seed)
    n = u.size
    speed_rpm = (states[:, 1] + NOISE["omega"] * rng.standard_normal(n)) * 60 / (2 * np.pi)
    current = (TRUTH["g"] * u - TRUTH["K"] * states[:, 1]) / TRUTH["R"]
    data = np.column_stack(
        [np.arange(n) * SAMPLE_PERIOD_S, u, states[:, 0], speed_rpm, current, u, np.ones(n)]
    )
    scipy.io.savemat(path, {"data": data, "fs": 1 / SAMPLE_PERIOD_S})


@pytest.mark.integration
def test_a_servos_speed_column_imported_fitted_and_validated_on_a_held_out_file(tmp_path, capsys):
    name, model_file = servo_model_file(tmp_path, "speed")
    runs = []
    for seed in (11, 12, 13):
        source = tmp_path / f"servo{seed}.mat"
        _servo_matrix(source, name, seed)
        runs.append(tmp_path / f"servo{seed}.mcap")
        # The speed column in rpm by MATLAB's 1-based syntax, the current by NumPy's 0-based
        # one (a recorded signal, not fitted); its noise unknown to the rig: estimated.
        argv = ["import", str(source), "--map", "data(:,1)=time:s", "--map", "data(:,2)=input:V:V"]
        argv += ["--map", "data(:,4)=output:rpm:omega", "--map", "data[:,4]=signal:A:i"]
        argv += ["--noise-std", "omega=estimate", "--variant", name, "--out", str(runs[-1])]
        assert main(argv) == 0, capsys.readouterr().err
    start = save_parameter_file(
        ParameterSet(name, {**TRUTH, "J": 2.0e-5, "B": 1.0e-5, "tau_c": 2.0e-3}, "start", "t"),
        tmp_path / "start.yaml",
    )
    capsys.readouterr()
    fit = ["fit", "--model-file", str(model_file), "--initial", str(start), "--fix", "g"]
    fit += ["--out-dir", str(tmp_path / "fits"), "--quiet", *map(str, runs[:2])]
    assert main(fit) == 0, capsys.readouterr().err
    fitted = next((tmp_path / "fits").glob("*.yaml"))
    estimates = load_parameter_file(fitted).values
    capsys.readouterr()
    # Two 2 s records at 0.5 rad/s: the speed-only fit's errors are ~0.1 % (J) to ~1 %
    # (friction); 2 % and 10 % bound them with room (test_output_fits.py measures tighter).
    assert estimates["J"] == pytest.approx(TRUTH["J"], rel=0.02)
    assert estimates["tau_c"] == pytest.approx(TRUTH["tau_c"], rel=0.1)
    assert estimates["B"] == pytest.approx(TRUTH["B"], rel=0.1)
    validate_argv = ["validate", str(fitted), str(runs[2]), "--model-file", str(model_file)]
    assert main([*validate_argv, "--json"]) == 0, capsys.readouterr().err
    report = json.loads(capsys.readouterr().out)
    (channel,) = report["recordings"][0]["results"][0]["channels"]
    assert (channel["name"], channel["unit"]) == ("omega", "rad/s")
    # Held out: the residual is the tachometer's noise (0.5 rad/s) within 5 % (2000 samples,
    # plus the estimates' small error); the speed swings ~600 rad/s, so the fit % is > 99.
    assert channel["residual_rms"] == pytest.approx(NOISE["omega"], rel=0.05)
    assert channel["simulation_fit_percent"] > 99.0
