"""Controller files as a user writes them: bad ones fail in one line, an unstable loop is a
result, and ``hframe-id control`` runs a declared model under a declared controller."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from hframe_id.cli import main
from hframe_id.resources import datasets_dir, models_dir

pytestmark = pytest.mark.integration

EMPS = str(datasets_dir() / "real" / "emps-estimation.mcap")
IDIM = str(models_dir() / "emps-idim-ls.yaml")
AXIS = str(models_dir() / "emps_axis.py")

#: A proportional position loop for the EMPS axis; the cases below break one item each.
GOOD = """
from hframe_id.control import Gain, declare_controller
from hframe_id.models import Signal


def law(y, r, z, g, T):
    return {"commands": {"vir": g["kp"] * (r["qg"] - y["qm"])}}


CONTROLLER = declare_controller(
    name="p-loop",
    description="proportional position loop",
    commands=[Signal("vir", "V", "drive voltage")],
    measured=["qm"],
    references=[Signal("qg", "m", "position reference")],
    gains=[Gain("kp", 2000.0, "V/m", "position gain")],
    law=law,
    limits={"vir": (-10.0, 10.0)},
)
"""


def _error_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert "Traceback" not in err
    return err


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("def law(y, r, z, g, T):", "def law(y, r, z, g, T)", "SyntaxError (line 6)"),
        ("CONTROLLER =", "OTHER =", "defines no CONTROLLER = declare_controller"),
        ('g["kp"]', 'g["kd"]', "uses undeclared gain 'kd'; declared: kp"),
        ('{"vir": g', '{"v": g', "law returns undeclared command(s) 'v'"),
        ('{"commands":', '{"command":', "unknown key(s) 'command'; valid: commands, states"),
        ('Signal("vir", "V",', 'Signal("vir", "",', "command 'vir' has no unit"),
        ('limits={"vir":', 'limits={"u":', "limits on 'u', which is not a command"),
        ("(-10.0, 10.0)", "(10.0, -10.0)", "limits of 'vir' must be finite with lower < upper"),
        ("law=law,", "law=law, delay_samples=-1,", "delay_samples must be an integer in 0..100"),
        ('g["kp"] * (', 'g["kp"] * undefined * (', "law: NameError (line 7)"),
        ('"qg"', '"q_ref"', "reads reference 'q_ref', which emps-estimation.mcap does not "
         "hold (signals: qg)"),
        ('"vir"', '"u"', "computes ['u'], but model emps-axis takes inputs ['vir']"),
        ('"qm"', '"x"', "reads output 'x', which model emps-axis does not have"),
    ],
)  # fmt: skip
def test_a_bad_controller_file_is_one_line_naming_file_and_item(
    tmp_path, capsys, old, new, message
):
    assert old in GOOD
    path = tmp_path / "controller.py"
    path.write_text(GOOD.replace(old, new))  # every occurrence: the law and the declaration
    code = main(["validate", IDIM, EMPS, "--model-file", AXIS, "--controller", str(path)])
    assert code == 2
    err = _error_line(capsys)
    assert message in err and str(path) in err


def test_missing_and_non_python_controller_files(tmp_path, capsys):
    assert main(["validate", IDIM, EMPS, "--controller", str(tmp_path / "none.py")]) == 2
    assert "controller file" in _error_line(capsys)
    text = tmp_path / "controller.txt"
    text.write_text(GOOD)
    assert main(["validate", IDIM, EMPS, "--controller", str(text)]) == 2
    assert "expected a Python file (.py)" in _error_line(capsys)


def test_an_unstable_loop_is_a_result_in_validate_and_an_error_in_control(tmp_path, capsys):
    """Positive feedback without a limit: the run grows until it is not finite. validate
    reports it as that parameter file's result; control refuses it in one line."""
    path = tmp_path / "unstable.py"
    path.write_text(
        GOOD.replace('Gain("kp", 2000.0', 'Gain("kp", -2000.0').replace(
            'limits={"vir": (-10.0, 10.0)},', ""
        )
    )
    argv = ["validate", IDIM, EMPS, "--controller", str(path)]
    assert main(argv) == 0
    assert "unstable closed loop: the simulation diverged at t = " in capsys.readouterr().out
    assert main([*argv, "--json"]) == 0
    closed = json.loads(capsys.readouterr().out)["recordings"][0]["results"][0]["closed_loop"]
    assert closed["stable"] is False and closed["relative_error_percent"] is None
    assert 0 < closed["diverged_at_s"] < 1
    control = ["control", "--params", IDIM, "--controller", str(path), "--reference", EMPS]
    assert main(control) == 2
    assert "unstable closed loop" in _error_line(capsys)


@pytest.mark.parametrize("command", ["validate", "control"])
def test_a_law_computing_nan_is_one_line(tmp_path, capsys, command):
    """A law that computes NaN from finite measurements: the saturation made it -10 V and the
    run went on as data (exit 0, a CSV of blank commands). The law's fault, named."""
    path = tmp_path / "nan.py"
    path.write_text(GOOD.replace('g["kp"] * (', 'float("nan") * g["kp"] * ('))
    argv = {
        "validate": ["validate", IDIM, EMPS, "--controller", str(path)],
        "control": ["control", "--params", IDIM, "--controller", str(path), "--reference",
                    EMPS, "--csv", str(tmp_path / "run.csv")],
    }[command]  # fmt: skip
    assert main([*argv, "--model-file", AXIS, "--quiet"]) == 2
    assert "the law computed vir = nan at t = 0 s" in _error_line(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["nan.py"]


def test_control_runs_a_declared_model_under_a_declared_controller(tmp_path, capsys):
    csv = tmp_path / "run.csv"
    controller = str(models_dir() / "emps_controller.py")
    argv = ["control", "--params", IDIM, "--model-file", AXIS, "--controller", controller,
            "--reference", EMPS, "--csv", str(csv)]  # fmt: skip
    assert main([*argv, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["variant"] == "emps-axis" and out["samples"] == 24841
    assert out["commands"]["vir"]["saturated_percent"] == 0.0
    # The simulated loop follows the recorded one to within 0.1 mm rms over 24.8 s.
    assert out["outputs"]["qm"]["rms_deviation"] < 1e-4
    signals = pd.read_csv(csv)
    assert {"qg [m]", "qm [m]", "qm_dot [m/s]", "vir command [V]", "vir applied [V]"} <= set(
        signals.columns
    )
    # One sample of delay: the applied voltage is the previous sample's command.
    assert signals["vir applied [V]"].iloc[1:].to_numpy() == pytest.approx(
        signals["vir command [V]"].iloc[:-1].to_numpy()
    )
    assert main(["control", "--params", IDIM, "--controller", "x.py"]) == 2
    assert "--controller needs --reference" in _error_line(capsys)
    assert main([*argv[:-2], "--kp", "150"]) == 2
    assert "--kp: for the H-frame PID" in _error_line(capsys)
