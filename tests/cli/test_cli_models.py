"""Command line: models, params, linearize, export, reduce (in-process through
``hframe_id.cli.main``, plus one run of the installed console script)."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from hframe_id.cli import main
from hframe_id.parameters import load_parameter_file
from hframe_id.parameters.reduce import reduce_to_hframe8

MODELS = Path(__file__).resolve().parents[2] / "models"
TABLE31 = str(MODELS / "hframe-20-table3.1.yaml")
TABLE41 = str(MODELS / "hframe-8-table4.1.yaml")
TABLE42 = str(MODELS / "hframe-8-table4.2.yaml")

# Table 5.2 (u1 -> phi1, hframe-8 with Table 4.1), rounded as printed: hence 0.1 %.
POLES = [-20.01 + 329.03j, -20.01 - 329.03j, -21.98 + 249.3j, -21.98 - 249.3j, -15.61, -43.9, 0, 0]
ZEROS = [-20.27 + 279.97j, -20.27 - 279.97j, -17.82 + 144j, -17.82 - 144j, -23.15, 0]


def run(capsys, *argv):
    """(exit code, stdout, stderr) of ``hframe-id argv``."""
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line_error(code, err, *fragments):
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hframe-id: error: "), err
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])


def match_printed(computed, printed):
    remaining = [complex(re, im) for re, im in computed]
    for value in printed:
        distances = [abs(c - value) for c in remaining]
        best = int(np.argmin(distances))
        assert distances[best] <= max(1e-3 * abs(value), 1e-6), (value, remaining[best])
        remaining.pop(best)
    assert not remaining


def test_models_lists_the_variants(capsys):
    code, out, _ = run(capsys, "models", "--json")
    assert code == 0
    # The thesis's variants first (model files loaded earlier in the process follow them).
    assert [m["variant"] for m in json.loads(out)][:3] == ["one-axis", "hframe-20", "hframe-8"]


# --- params ----------------------------------------------------------------------------------


def test_params_show(capsys):
    code, out, _ = run(capsys, "params", "show", TABLE42)
    assert code == 0
    assert "model: hframe-8" in out
    assert "source: Sollmann 2007, Table 4.1 with Table 4.2's friction" in out
    header = next(line for line in out.splitlines() if line.startswith("name"))
    assert header.split() == ["name", "unit", "value", "description"]
    rows = {line.split()[0]: line for line in out.splitlines()[out.splitlines().index(header) :]}
    assert "N/m" in rows["k_l"] and "13167.0" in rows["k_l"]
    assert "N m" in rows["tau_cM1"] and "0.05" in rows["tau_cM1"]
    assert len(load_parameter_file(TABLE42).values) == len(rows) - 2  # minus title, rule


def test_params_check_ok_and_bad(capsys, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(Path(TABLE41).read_text().replace("k_l [N/m]", "k_ll [N/m]"))
    code, out, _ = run(capsys, "params", "check", TABLE41, TABLE31)
    assert code == 0
    assert out.count(": ok (") == 2
    code, out, err = run(capsys, "params", "check", TABLE41, str(bad))
    assert_one_line_error(code, err, str(bad), "'k_ll [N/m]'", "did you mean 'k_l [N/m]'")
    assert f"{TABLE41}: ok" in out


def test_params_show_missing_file(capsys, tmp_path):
    code, _, err = run(capsys, "params", "show", str(tmp_path / "none.yaml"))
    assert_one_line_error(code, err, "none.yaml", "no such parameter file")


# --- linearize -------------------------------------------------------------------------------


def test_linearize_json_reproduces_table_5_2(capsys):
    code, out, _ = run(capsys, "linearize", TABLE41, "--input", "u1", "--output", "phi1", "--json")
    assert code == 0
    report = json.loads(out)
    match_printed(report["poles"], POLES)
    match_printed(report["zeros"], ZEROS)
    assert report["model"] == "hframe-8"
    assert report["units"]["poles"] == "rad/s"
    assert len(report["natural_frequencies"]) == len(report["damping"]) == 8
    assert report["notes"] == []


def test_linearize_notes_coulomb_exclusion(capsys):
    code, out, _ = run(capsys, "linearize", TABLE42, "--input", "u1", "--output", "phi1", "--json")
    assert code == 0
    assert "Coulomb friction is excluded" in json.loads(out)["notes"][0]
    code, out, _ = run(capsys, "linearize", TABLE42)
    assert "note: Coulomb friction is excluded" in out


def test_linearize_text_and_all_pairs(capsys):
    code, out, _ = run(capsys, "linearize", TABLE41)
    assert code == 0
    assert "poles (8):" in out and "rad/s" in out
    assert out.count("zeros of ") == 8  # 2 inputs x 4 outputs
    assert "zeros of u1 [V] -> phi1 [rad] (6):" in out
    assert "-20.0068" in out  # Table 5.2's -20.01 + 329.03i
    code, out, _ = run(capsys, "linearize", TABLE41, "--input", "u2", "--json")
    pairs = json.loads(out)["pairs"]
    assert [(p["input"], p["output"]) for p in pairs] == [
        ("u2", "phi1"),
        ("u2", "phi2"),
        ("u2", "x"),
        ("u2", "y"),
    ]


def test_linearize_one_axis_full_system(capsys):
    code, out, _ = run(capsys, "linearize", str(MODELS / "one-axis-table2.1.yaml"), "--json")
    assert code == 0
    report = json.loads(out)
    assert len(report["poles"]) == 6
    assert [p["output"] for p in report["pairs"]] == ["phi1", "x"]


@pytest.mark.parametrize(
    ("args", "fragments"),
    [
        (["--input", "u3"], ["no input named 'u3'", "valid: u1, u2"]),
        (["--output", "phi_1"], ["no output named 'phi_1'", "did you mean 'phi1'"]),
        (["--output", "theta"], ["no output named 'theta'", "valid: phi1, phi2, x, y"]),
    ],
)
def test_linearize_unknown_signal(capsys, args, fragments):
    code, out, err = run(capsys, "linearize", TABLE41, *args)
    assert_one_line_error(code, err, *fragments)
    assert out == ""


# --- export ----------------------------------------------------------------------------------


def test_export_json_to_stdout(capsys):
    code, out, _ = run(capsys, "export", TABLE41, "--format", "json")
    assert code == 0
    doc = json.loads(out)
    assert {(p["name"], p["unit"]) for p in doc["parameters"]} >= {("k_l", "N/m"), ("R", "ohm")}
    assert {p["name"]: p["value"] for p in doc["parameters"]} == load_parameter_file(TABLE41).values


@pytest.mark.parametrize(
    ("fmt", "name"),
    [
        ("statespace", "ss.json"),
        ("matlab", "ss.mat"),
        ("matlab-script", "hframe8.m"),
        ("python-control", "hframe8.py"),
        ("csv", "p.csv"),
        ("json", "p.json"),
    ],
)
def test_export_to_file(capsys, tmp_path, fmt, name):
    path = tmp_path / name
    code, out, err = run(capsys, "export", TABLE41, "--format", fmt, "--out", str(path))
    assert code == 0 and out == ""
    assert f"wrote {path}" in err
    assert path.stat().st_size > 100
    assert [p.name for p in tmp_path.iterdir()] == [name]


def test_export_matlab_file_content(capsys, tmp_path):
    path = tmp_path / "ss.mat"
    assert main(["export", TABLE41, "--format", "matlab", "--out", str(path)]) == 0
    mat = scipy.io.loadmat(path)
    assert mat["A"].shape == (8, 8) and mat["B"].shape == (8, 2)
    assert [str(c[0]) for c in mat["OutputName"].ravel()] == ["phi1", "phi2", "x", "y"]


def test_export_refuses_to_overwrite_without_force(capsys, tmp_path):
    path = tmp_path / "ss.json"
    path.write_text("keep me")
    code, _, err = run(capsys, "export", TABLE41, "--format", "statespace", "--out", str(path))
    assert_one_line_error(code, err, str(path), "exists already", "--force")
    assert path.read_text() == "keep me"
    code, _, _ = run(
        capsys, "export", TABLE41, "--format", "statespace", "--out", str(path), "--force"
    )
    assert code == 0
    assert json.loads(path.read_text())["model"] == "hframe-8"


@pytest.mark.parametrize(
    ("args", "fragments"),
    [
        (["--format", "matlb"], ["unknown export format 'matlb'", "did you mean 'matlab'"]),
        (["--format", "matlab"], ["matlab", "give --out PATH"]),
    ],
)
def test_export_bad_format(capsys, tmp_path, args, fragments):
    code, out, err = run(capsys, "export", TABLE41, *args)
    assert_one_line_error(code, err, *fragments)
    assert out == ""


def test_export_errors_write_nothing(capsys, tmp_path):
    target = tmp_path / "out.mat"
    code, _, err = run(
        capsys, "export", str(tmp_path / "none.yaml"), "--format", "matlab", "--out", str(target)
    )
    assert_one_line_error(code, err, "none.yaml", "no such parameter file")
    code, _, err = run(capsys, "export", TABLE41, "--format", "mat", "--out", str(target))
    assert_one_line_error(code, err, "unknown export format 'mat'")
    assert list(tmp_path.iterdir()) == []


# --- reduce ----------------------------------------------------------------------------------


def test_reduce_writes_an_hframe8_file(capsys, tmp_path):
    out_path = tmp_path / "hframe-8-from-table3.1.yaml"
    code, out, _ = run(capsys, "reduce", TABLE31, "--out", str(out_path))
    assert code == 0
    assert f"wrote {out_path}" in out
    written = load_parameter_file(out_path, variant="hframe-8")
    assert written.values == reduce_to_hframe8(load_parameter_file(TABLE31)).values
    assert written.values["k_l"] == pytest.approx(13167.0, rel=1e-4)  # Table 4.1


def test_reduce_errors_write_nothing(capsys, tmp_path):
    out_path = tmp_path / "r.yaml"
    code, _, err = run(capsys, "reduce", TABLE41, "--out", str(out_path))
    assert_one_line_error(code, err, TABLE41, "needs an hframe-20", "hframe-8")
    code, _, err = run(capsys, "reduce", str(tmp_path / "none.yaml"), "--out", str(out_path))
    assert_one_line_error(code, err, "no such parameter file")
    assert list(tmp_path.iterdir()) == []
    out_path.write_text("keep me")
    code, _, err = run(capsys, "reduce", TABLE31, "--out", str(out_path))
    assert_one_line_error(code, err, "exists already")
    assert out_path.read_text() == "keep me"
    assert run(capsys, "reduce", TABLE31, "--out", str(out_path), "--force")[0] == 0
    assert load_parameter_file(out_path).variant == "hframe-8"


def test_missing_required_option_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as info:
        main(["reduce", TABLE31])
    assert info.value.code == 2
    assert "--out" in capsys.readouterr().err


# --- the installed console script ------------------------------------------------------------


@pytest.mark.integration
def test_console_script_linearize_json():
    script = shutil.which("hframe-id", path=str(Path(sys.executable).parent))
    assert script, "the hframe-id console script is not installed next to this Python"
    done = subprocess.run(
        [script, "linearize", TABLE41, "--input", "u1", "--output", "phi1", "--json"],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    match_printed(report["poles"], POLES)
    match_printed(report["zeros"], ZEROS)
    bad = subprocess.run(
        [script, "linearize", TABLE41, "--input", "u9"],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert bad.returncode == 2
    assert bad.stderr.strip().startswith("hframe-id: error: hframe-8 has no input named 'u9'")
