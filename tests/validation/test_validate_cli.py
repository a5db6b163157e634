"""`hframe-id validate` end to end on a shipped recording: text, JSON, plots, one-line errors."""

import json
from pathlib import Path

from hframe_id.cli import main

ROOT = Path(__file__).resolve().parents[2]
TRUTH = str(ROOT / "datasets" / "truth" / "hframe-8-rig.yaml")
TABLE = str(ROOT / "models" / "hframe-8-table4.2.yaml")


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("hframe-id: error:"), err
    return err


def test_json_output_parses_with_a_schema_version(capsys):
    # the plant's own parameters on its recording: fits near 100 % on the moving channels
    status = main(["validate", TRUTH, "4V_xmotion.mcap", "--params", TABLE, "--json",
                   "--horizon", "5"])  # fmt: skip
    assert status == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["schema_version"] == 1
    assert doc["options"]["horizon_samples"] == 5
    assert [p["label"] for p in doc["parameter_files"]] == [
        "hframe-8-rig.yaml",
        TABLE.split("/")[-1],
    ]
    (rec,) = doc["recordings"]
    truth, table = rec["results"]
    channels = {c["name"]: c for c in truth["channels"]}
    assert set(channels) == {"phi1", "phi2", "x", "y"}
    # x moves 3.5 cm against 5 um laser noise: the plant's own parameters fit to > 99.9 %
    assert channels["x"]["simulation_fit_percent"] > 99.9
    assert channels["x"]["prediction_fit_percent"] > 99.9
    assert channels["x"]["unit"] == "m"
    assert len(channels["x"]["autocorrelation"]["values"]) == 26
    assert set(channels["x"]["cross_correlation"]) == {"u1", "u2"}
    # Table 4.2 is not the drifted plant: a worse simulation fit on every channel
    for ch in table["channels"]:
        assert ch["simulation_fit_percent"] < channels[ch["name"]]["simulation_fit_percent"]


def test_plots_are_written(tmp_path, capsys):
    out = tmp_path / "plots"
    status = main(["validate", TRUTH, "4V_xmotion.mcap", "--horizon", "0", "--plot", str(out)])
    assert status == 0
    assert "fit [%]" in capsys.readouterr().out
    names = sorted(p.name for p in out.iterdir())
    assert names == ["4V_xmotion-compare.png", "4V_xmotion-resid-hframe-8-rig.png"]
    assert all(p.read_bytes()[:4] == b"\x89PNG" for p in out.iterdir())


def test_bad_input_exits_2_with_one_line_and_writes_nothing(tmp_path, capsys):
    one_axis = str(ROOT / "models" / "one-axis-table2.3.yaml")
    assert main(["validate", one_axis, "4V_xmotion.mcap"]) == 2
    assert "takes inputs" in _one_line_error(capsys)
    assert main(["validate", TABLE, "4V_xmotion.mcap", "5V_oneaxis.mcap"]) == 2
    assert "different rigs" in _one_line_error(capsys)
    assert main(["validate", TABLE, "no-such.mcap"]) == 2
    assert "no such recording" in _one_line_error(capsys)
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert main(["validate", TABLE, "4V_xmotion.mcap", "--plot", str(blocker / "x")]) == 2
    assert "--plot" in _one_line_error(capsys)
    assert main(["validate", TABLE, "4V_xmotion.mcap", "--horizon", "-1"]) == 2
    assert "horizon" in _one_line_error(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]
