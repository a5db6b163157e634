"""``--json`` of inspect, params show/check, datasets list/verify, simulate and record: one
object on stdout in the versioned envelope of docs/cli-json.md; and what the human output
states about clamped voltages and incomplete recordings."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import pytest

from hframe_id.cli import main
from hframe_id.cli.json_output import SCHEMA_VERSION

ROOT = Path(__file__).resolve().parents[2]
H8 = ROOT / "models" / "hframe-8-table4.2.yaml"
REC = ROOT / "datasets" / "4V_xmotion.mcap"
EMPS = ROOT / "datasets" / "real" / "emps-estimation.mcap"


def _json(capsys, command: str, argv: list[str], status: int = 0) -> dict:
    assert main(argv) == status
    doc = json.loads(capsys.readouterr().out)
    assert doc["schema_version"] == SCHEMA_VERSION
    assert doc["command"] == command and doc["software"].startswith("hframe-id ")
    return doc


@pytest.fixture(scope="module")
def half(tmp_path_factory) -> Path:
    """4V_xmotion.mcap cut after 60 kB: a killed writer's file, 500 of 1000 samples salvaged."""
    path = tmp_path_factory.mktemp("cut") / "half.mcap"
    path.write_bytes(REC.read_bytes()[:60_000])
    return path


def test_inspect_json_has_units_ranges_and_completeness(capsys):
    doc = _json(capsys, "inspect", ["inspect", str(EMPS), "--json"])
    assert doc["variant"] == "emps-axis" and doc["samples"] == 24841 and doc["finished"]
    assert doc["inputs"][0] | {"min": 0, "max": 0} == {
        "name": "vir",
        "unit": "V",
        "min": 0,
        "max": 0,
    }
    assert doc["outputs"][0]["unit"] == "m" and doc["outputs"][0]["valid_share"] == 1.0
    assert doc["signals"] == [
        {"name": "qg", "unit": "m", "min": 0.0, "max": doc["signals"][0]["max"]}
    ]
    assert doc["completeness"]["planned"] is None and doc["completeness"]["statement"] is None


def test_inspect_states_a_salvaged_recording_and_its_lost_share(half, capsys):
    doc = _json(capsys, "inspect", ["inspect", str(half), "--json"])
    done = doc["completeness"]
    assert (done["samples"], done["planned"], done["truncated"]) == (500, 1000, True)
    assert done["lost_share"] == 0.5 and "50.0 % lost" in done["statement"]
    assert not doc["finished"] and "recovered 500 samples" in doc["warnings"][0]
    assert main(["inspect", str(half)]) == 0
    text = capsys.readouterr().out
    assert "recorded       500 of 1000 planned samples (50.0 % lost)" in text
    assert "output         x [m]:" in text and "input          u1 [V]:" in text
    # a killed writer's file has no stop event: "aborted no" misstated it (issue 27)
    assert "aborted        unknown: the run ended without a stop event" in text


def test_inspect_plots_every_output_and_signal_in_its_unit(tmp_path, capsys):
    from matplotlib.axes import Axes

    labels = []
    original = Axes.set_ylabel
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(
            Axes, "set_ylabel", lambda ax, text, **k: labels.append(text) or original(ax, text, **k)
        )
        assert main(["inspect", str(EMPS), "--plot", str(tmp_path / "e.png")]) == 0
    assert labels == ["input [V]", "output [m]"]
    assert (tmp_path / "e.png").stat().st_size > 10_000


def test_params_show_and_check_json(tmp_path, capsys):
    doc = _json(capsys, "params show", ["params", "show", str(H8), "--json"])
    assert doc["model"] == "hframe-8"
    row = next(p for p in doc["parameters"] if p["name"] == "k_l")
    assert row == {
        "name": "k_l",
        "unit": "N/m",
        "value": 13167.0,
        "description": row["description"],
    }
    bad = tmp_path / "bad.yaml"
    bad.write_bytes(b"\x80\x81")
    doc = _json(capsys, "params check", ["params", "check", str(H8), str(bad), "--json"], 2)
    assert doc["ok"] is False
    assert doc["files"][0] == {"file": str(H8), "ok": True, "model": "hframe-8", "parameters": 21}
    assert doc["files"][1]["ok"] is False and "not UTF-8" in doc["files"][1]["error"]


def test_datasets_list_and_verify_json(capsys):
    doc = _json(capsys, "datasets list", ["datasets", "list", "--json"])
    files = [d["file"] for d in doc["datasets"]]
    assert "4V_xmotion.mcap" in files
    assert all(set(d) == {"file", "truth", "seed", "description"} for d in doc["datasets"])
    doc = _json(
        capsys, "datasets verify", ["datasets", "verify", "--dir", str(ROOT / "datasets"), "--json"]
    )
    assert doc["ok"] is True and doc["problems"] == []


def test_simulate_json(tmp_path, capsys):
    out = tmp_path / "s.csv"
    argv = [
        "simulate",
        "--params",
        str(H8),
        "--step",
        "1,4",
        "--duration",
        "0.05",
        "--out",
        str(out),
        "--json",
    ]
    doc = _json(capsys, "simulate", argv)
    assert doc["csv"] == str(out) and out.exists() and doc["samples"] == 50
    assert [o["name"] for o in doc["outputs"]] == ["phi1", "phi2", "x", "y"]
    assert doc["outputs"][0]["unit"] == "rad" and doc["outputs"][0]["final"] > 0
    assert doc["mcap"] is None and doc["plot"] is None


def test_record_states_a_clamped_voltage(tmp_path, capsys):
    argv = ["record", "--rig", "sim", "--params", str(H8), "--v1", "400", "--v2", "4", "--step",
            "0.05", "--duration", "0.1", "--fast", "--out", str(tmp_path / "r.mcap")]  # fmt: skip
    doc = _json(capsys, "record", [*argv, "--json"])
    assert doc["samples"] == doc["planned_samples"] == 100 and doc["lost_share"] == 0.0
    assert doc["clamped"] == [
        {"input": "u1", "requested_V": 400.0, "applied_V": 10.0, "samples": 50}
    ]
    assert main([*argv, "--overwrite"]) == 0
    captured = capsys.readouterr()
    sentence = (
        "u1 asks for 400 V, outside the DAC range [-10, 10] V: clamped to 10 V in 50 sample(s)"
    )
    assert f"clamped        {sentence}" in captured.out
    assert captured.err.strip() == f"hframe-id: warning: {sentence}"


def test_fit_report_names_an_incomplete_recording(half):
    from hframe_id.fitting.report import incomplete_recordings
    from hframe_id.recordings import read_recording

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        recordings = [read_recording(half), read_recording(REC)]
    assert incomplete_recordings(recordings) == [
        "half.mcap: 500 of 1000 planned samples (50.0 % lost): the file was unfinished "
        "(writer killed) and salvaged"
    ]


def test_a_library_warning_reaches_the_user_as_one_line(half, tmp_path, capsys):
    out = tmp_path / "s.csv"
    assert main(["simulate", "--params", str(H8), "--recording", str(half), "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert err.startswith("hframe-id: warning: ") and err.count("\n") == 1
    assert ".py" not in err


def _strict(text: str) -> dict:
    """``text`` parsed as JSON, refusing NaN and Infinity (which no JSON reader accepts)."""

    def refuse(constant: str) -> None:
        raise ValueError(f"{constant} is not JSON")

    return json.loads(text, parse_constant=refuse)


def test_fleet_report_from_a_zero_baseline(tmp_path, capsys):
    """A friction fitted to zero in a rig's first run: fleet report printed numpy's division
    warning and --json wrote "change": Infinity; now null, and no warning."""
    from datetime import UTC, datetime

    from fit_rows import stored_fits

    runs = [("k0", "rig-01", datetime(2026, 1, 5, tzinfo=UTC), 0.0),
            ("k1", "rig-01", datetime(2026, 1, 12, tzinfo=UTC), 100.0)]  # fmt: skip
    results = stored_fits(tmp_path / "r.parquet", runs)
    assert main(["fleet", "report", str(results), "--json", "--out", str(tmp_path / "rep")]) == 0
    captured = capsys.readouterr()
    assert captured.err == ""
    (drift,) = _strict(captured.out)["flagged"]
    assert drift["change"] is None and drift["baseline"] == 0.0


def test_fleet_report_of_a_parameter_no_fit_has(tmp_path, capsys):
    """A parameter without a value in any converged fit: matplotlib's 'No artists with labels
    found to put in legend' reached the user; now it has no plot."""
    from datetime import UTC, datetime

    from fit_rows import stored_fits

    results = stored_fits(
        tmp_path / "r.parquet", [("k0", "rig-01", datetime(2026, 1, 5, tzinfo=UTC), math.nan)]
    )
    assert main(["fleet", "report", str(results), "--out", str(tmp_path / "rep")]) == 0
    assert capsys.readouterr().err == ""
    assert not (tmp_path / "rep" / "plots" / "k_l.png").exists()
