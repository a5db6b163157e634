"""``hframe-id design``: a run writes a playable CSV, its report and plot; bad input is one
error line, exit status 2, and nothing written."""

import json
from pathlib import Path

import numpy as np
import pytest

from hframe_id.cli import main
from hframe_id.rig.protocols import load_sequence_csv
from tests.cli.refusals import refused

MODELS = Path(__file__).resolve().parents[2] / "models"
TABLE = MODELS / "hframe-8-table4.2.yaml"
THESIS_TRAVEL = ["--travel", "x=-0.2:0.2", "--travel", "y=-0.2:0.2"]


def argv(out, *extra, params=TABLE, volts="6", travel=THESIS_TRAVEL):
    # --quiet: a refusal found after 2 s of work would follow the progress line
    return [
        "design", "--params", params, "--duration", "1", "--max-voltage", volts,
        *travel, "--out", out, "--draws", "0", "--quiet", *extra,
    ]  # fmt: skip


def test_design_writes_csv_report_and_plot(tmp_path, capsys):
    out = tmp_path / "design.csv"
    assert main([str(a) for a in argv(out, "--json")]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["command"] == "design" and payload["criterion"] == "D-optimal"
    labels = [p["label"] for p in payload["predictions"]]
    assert labels == ["design", "six steps (thesis)", "PRBS", "multisine"]
    table = load_sequence_csv(out).table(1e-3)
    assert table.shape == (1000, 2) and np.max(np.abs(table)) <= 6.0
    report = (tmp_path / "design.md").read_text()
    for name in ("k_l [N/m]", "F_c_cart [N]", "PRBS", "multisine", "six steps", "design.png"):
        assert name in report
    assert (tmp_path / "design.png").stat().st_size > 0


@pytest.mark.parametrize(
    ("change", "named"),
    [
        ({"travel": ["--travel", "x=0.1:0.3", "--travel", "y=-0.2:0.2"]}, ["--travel", "0.1"]),
        ({"travel": ["--travel", "x=-0.2:0.2"]}, ["--travel y"]),
        ({"travel": ["--travel", "z=-1:1", "--travel", "y=-0.2:0.2"]}, ["--travel", "z=-1:1"]),
        ({"volts": "12"}, ["--max-voltage", "12"]),
        ({"params": MODELS / "one-axis-table2.3.yaml"}, ["one-axis-table2.3.yaml", "one-axis"]),
        ({"params": MODELS / "missing.yaml"}, ["missing.yaml"]),
    ],
)
def test_bad_input_is_refused_before_any_work(tmp_path, capsys, change, named):
    out = tmp_path / "design.csv"
    refused(argv(out, **change), capsys, *named)
    assert not any(tmp_path.iterdir())


def test_a_voltage_below_one_dac_step_informs_nothing(tmp_path, capsys):
    """0.001 V rounds to 0 V at the 12-bit DAC (4.9 mV steps): the model never moves."""
    out = tmp_path / "design.csv"
    refused(argv(out, volts="0.001"), capsys, "no free parameter with information", "0.001")
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize(
    ("option", "value", "suggested"),
    [("--focus", "F_c_crt", "F_c_cart"), ("--free", "k_q", "k_r")],
)
def test_focus_and_free_name_parameters(tmp_path, capsys, option, value, suggested):
    out = tmp_path / "design.csv"
    refused(argv(out, option, value, "--draws", "2"), capsys, option, value, suggested)
    assert not any(tmp_path.iterdir())


def test_existing_outputs_need_force(tmp_path, capsys):
    (tmp_path / "design.md").write_text("mine")
    refused(argv(tmp_path / "design.csv"), capsys, "design.md", "--force")
    assert (tmp_path / "design.md").read_text() == "mine"


def test_a_travel_no_block_keeps_is_refused(tmp_path, capsys):
    """+/-0.1 mm inside the margin: even 16 doublets in 0.5 s move the model farther."""
    out = tmp_path / "design.csv"
    travel = ["--travel", "x=-0.0101:0.0101", "--travel", "y=-0.0101:0.0101"]
    refused(argv(out, "--margin", "0.01", travel=travel), capsys, "--travel", "every candidate")
    assert not any(tmp_path.iterdir())


def test_recordings_to_add_or_calibrate_with_must_be_recordings(tmp_path, capsys):
    text = tmp_path / "notes.mcap"
    text.write_text("not a recording")
    refused(argv(tmp_path / "design.csv", "--after", text), capsys, "notes.mcap")
    assert [p.name for p in tmp_path.iterdir()] == ["notes.mcap"]


def test_calibrating_a_table_that_reports_no_errors_is_refused(tmp_path, capsys):
    """Calibration compares a fit's reported errors with the predicted ones: a table has
    none to compare with."""
    recording = tmp_path / "step.mcap"
    record = "record --rig sim --protocol step --v1 2 --v2 2 --step 0.2 --duration 0.3 --fast"
    options = [*record.split(), "--quiet", "--params", TABLE, "--out", recording]
    assert main([str(a) for a in options]) == 0
    capsys.readouterr()
    refused(argv(tmp_path / "design.csv", "--calibrate", recording), capsys, "--calibrate")
    assert [p.name for p in tmp_path.iterdir()] == ["step.mcap"]
