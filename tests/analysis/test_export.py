"""Exporters (hframe_id.analysis.export): every format reproduces the parameters or the
linearization exactly, names its signals with units, and writes files atomically."""

import csv
import importlib.util
import io
import json
import re
import stat
from pathlib import Path

import numpy as np
import pytest
import scipy.io
import scipy.signal

from hframe_id.analysis import export
from hframe_id.analysis.linear import COULOMB_NOTE, linearize
from hframe_id.errors import ModelError, OptionError
from hframe_id.parameters import load_parameter_file

MODELS = Path(__file__).resolve().parents[2] / "models"
TABLE41 = MODELS / "hframe-8-table4.1.yaml"
TABLE42 = MODELS / "hframe-8-table4.2.yaml"


@pytest.fixture(scope="module")
def params():
    return load_parameter_file(TABLE41)


@pytest.fixture(scope="module")
def lin(params):
    return linearize(params)


# --- parameters ------------------------------------------------------------------------------


def test_json_has_every_parameter_with_unit_and_value(params):
    doc = json.loads(export.render(params, "json"))
    assert doc["model"] == "hframe-8"
    assert doc["source"] == "Sollmann 2007, Table 4.1"
    assert doc["title"] and doc["references"]
    rows = {row["name"]: row for row in doc["parameters"]}
    assert set(rows) == set(params.values)
    for name, value in params.values.items():
        assert rows[name]["value"] == value  # exact: JSON floats are shortest round-trip
        assert rows[name]["unit"]
        assert rows[name]["description"]
    assert rows["k_l"]["unit"] == "N/m"
    assert rows["J_M1"]["unit"] == "kg m^2"


def test_csv_reads_back_exactly(params):
    rows = list(csv.DictReader(io.StringIO(export.render(params, "csv"))))
    assert [r["name"] for r in rows][:4] == ["r", "k_l", "k_r", "k_b"]
    assert {r["name"]: float(r["value"]) for r in rows} == params.values
    assert {r["name"]: r["unit"] for r in rows}["b_cart"] == "N s/m"


# --- state space -------------------------------------------------------------------------------


def test_statespace_json(params, lin):
    doc = json.loads(export.render(params, "statespace"))
    for name in "ABCD":
        np.testing.assert_array_equal(np.array(doc[name]), getattr(lin, name))
    assert [s["name"] for s in doc["states"]] == list(lin.states)
    assert {s["name"]: s["unit"] for s in doc["states"]}["phi1_dot"] == "rad/s"
    assert doc["inputs"] == [{"name": "u1", "unit": "V"}, {"name": "u2", "unit": "V"}]
    assert [s["unit"] for s in doc["outputs"]] == ["rad", "rad", "m", "m"]
    assert doc["notes"] == []
    assert "continuous" in doc["linearization"]


def test_statespace_notes_coulomb_exclusion():
    doc = json.loads(export.render(load_parameter_file(TABLE42), "statespace"))
    assert doc["notes"] == [COULOMB_NOTE]
    assert doc["file_notes"].startswith("Table 4.1 stiffness")


def _load_mat(data: bytes) -> dict:
    return scipy.io.loadmat(io.BytesIO(data))


def _cellstr(cell) -> list[str]:
    return [str(item[0]) for item in cell.ravel()]


def test_mat_file_loads_with_matrices_names_and_units(params, lin):
    mat = _load_mat(export.render(params, "matlab"))
    for name in "ABCD":
        np.testing.assert_array_equal(mat[name], getattr(lin, name))
    assert _cellstr(mat["StateName"]) == list(lin.states)
    assert _cellstr(mat["StateUnit"]) == list(lin.state_units)
    assert _cellstr(mat["InputName"]) == ["u1", "u2"]
    assert _cellstr(mat["InputUnit"]) == ["V", "V"]
    assert _cellstr(mat["OutputName"]) == ["phi1", "phi2", "x", "y"]
    assert _cellstr(mat["OutputUnit"]) == ["rad", "rad", "m", "m"]
    assert mat["StateName"].shape == (8, 1)  # column cell arrays, as MATLAB's ss expects
    assert str(mat["model"][0]) == "hframe-8"
    assert float(mat["params"]["k_l"][0, 0].squeeze()) == params.values["k_l"]
    assert str(mat["param_units"]["k_l"][0, 0][0]) == "N/m"
    # a control tool builds the system from it (scipy.signal here; python-control below)
    system = scipy.signal.StateSpace(mat["A"], mat["B"], mat["C"], mat["D"])
    assert system.A.shape == (8, 8) and system.B.shape == (8, 2) and system.C.shape == (4, 8)


def test_mat_file_builds_a_python_control_system(params, lin):
    control = pytest.importorskip("control")
    mat = _load_mat(export.render(params, "matlab"))
    system = control.ss(
        mat["A"],
        mat["B"],
        mat["C"],
        mat["D"],
        states=_cellstr(mat["StateName"]),
        inputs=_cellstr(mat["InputName"]),
        outputs=_cellstr(mat["OutputName"]),
    )
    assert system.output_labels == ["phi1", "phi2", "x", "y"]


def _matlab_matrix(script: str, name: str) -> np.ndarray:
    body = re.search(rf"^{name} = \[\n(.*?)\n\];", script, re.S | re.M).group(1)
    return np.array([[float(v) for v in row.split()] for row in body.split(";\n")])


def _matlab_cell(script: str, prop: str) -> list[str]:
    body = re.search(rf"'{prop}', \{{(.*?)\}}", script).group(1)
    return [item.strip().strip("'") for item in body.split(";")]


def test_matlab_script_reproduces_the_matrices_exactly(params, lin):
    script = export.render(params, "matlab-script")
    for name in "ABCD":
        np.testing.assert_array_equal(_matlab_matrix(script, name), getattr(lin, name))
    assert _matlab_cell(script, "StateName") == list(lin.states)
    assert _matlab_cell(script, "StateUnit") == list(lin.state_units)
    assert _matlab_cell(script, "InputUnit") == ["V", "V"]
    assert _matlab_cell(script, "OutputName") == ["phi1", "phi2", "x", "y"]
    assert "sys = ss(A, B, C, D" in script
    assert script.startswith("% hframe-8: ")
    # comments only before the assignments, so that MATLAB's `help` shows the header
    assert all(line.startswith("%") for line in script.splitlines()[:4])


def _import_script(text: str, tmp_path: Path):
    path = tmp_path / "linear_model.py"
    path.write_text(text)
    spec = importlib.util.spec_from_file_location("linear_model", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_python_control_script_reproduces_the_matrices_exactly(params, lin, tmp_path):
    module = _import_script(export.render(params, "python-control"), tmp_path)
    for name in "ABCD":
        np.testing.assert_array_equal(getattr(module, name), getattr(lin, name))
    assert module.STATES == lin.states
    assert module.STATE_UNITS == lin.state_units
    assert module.INPUTS == ("u1", "u2")
    assert module.OUTPUT_UNITS == ("rad", "rad", "m", "m")
    assert "Table 4.1" in module.__doc__


def test_python_control_script_builds_a_named_system(params, lin, tmp_path):
    control = pytest.importorskip("control")
    module = _import_script(export.render(params, "python-control"), tmp_path)
    system = module.ss()
    assert isinstance(system, control.StateSpace)
    assert system.state_labels == list(lin.states)
    assert system.input_labels == ["u1", "u2"]


def test_one_axis_statespace_exports():
    params = load_parameter_file(MODELS / "one-axis-table2.1.yaml")
    doc = json.loads(export.render(params, "statespace"))
    assert [s["name"] for s in doc["outputs"]] == ["phi1", "x"]
    assert np.array(doc["B"]).shape == (6, 1)


def test_unknown_format_suggests_the_nearest(params):
    with pytest.raises(OptionError, match="unknown export format 'matlb'.*did you mean 'matlab'"):
        export.render(params, "matlb")
    with pytest.raises(OptionError, match="valid: json, csv"):
        export.export_format("yaml2")


# --- pole-zero report --------------------------------------------------------------------------


def test_pole_zero_report_siso(params):
    report = export.pole_zero_report(params, inputs=["u1"], outputs=["phi1"])
    assert report["input"] == "u1" and report["output"] == "phi1"
    assert len(report["poles"]) == 8 and len(report["zeros"]) == 6
    assert report["units"]["poles"] == "rad/s"
    assert report["notes"] == []
    # Table 5.2's first pole pair, to its printed rounding (0.1 %)
    assert any(abs(complex(*z) - (-20.01 + 329.03j)) < 0.33 for z in report["poles"])
    for (re_, im), omega, zeta in zip(
        report["poles"], report["natural_frequencies"], report["damping"], strict=True
    ):
        assert omega == pytest.approx(abs(complex(re_, im)))
        assert zeta == pytest.approx(-re_ / omega if omega else 1.0)
    assert len(report["zero_natural_frequencies"]) == 6


def test_pole_zero_report_all_pairs_and_coulomb_note():
    report = export.pole_zero_report(load_parameter_file(TABLE42))
    assert "zeros" not in report  # more than one pair
    assert [(p["input"], p["output"]) for p in report["pairs"]][:2] == [
        ("u1", "phi1"),
        ("u1", "phi2"),
    ]
    assert len(report["pairs"]) == 8
    assert report["notes"] == [COULOMB_NOTE]


@pytest.mark.parametrize(
    ("inputs", "outputs", "hint"),
    [(["u3"], None, "input named 'u3'"), (None, ["phi_1"], "did you mean 'phi1'")],
)
def test_pole_zero_report_unknown_signal(params, inputs, outputs, hint):
    with pytest.raises(ModelError, match=hint):
        export.pole_zero_report(params, inputs=inputs, outputs=outputs)


# --- files -----------------------------------------------------------------------------------


def test_write_atomic_refuses_to_overwrite(tmp_path):
    path = export.write_atomic(tmp_path / "a.json", "first")
    with pytest.raises(OptionError, match="exists already; use --force"):
        export.write_atomic(path, "second")
    assert path.read_text() == "first"
    export.write_atomic(path, b"third", overwrite=True)
    assert path.read_bytes() == b"third"
    assert [p.name for p in tmp_path.iterdir()] == ["a.json"]  # no temporary files left
    mode = stat.S_IMODE(path.stat().st_mode)
    assert mode & stat.S_IRUSR and mode & stat.S_IWUSR


def test_write_atomic_bad_targets(tmp_path):
    with pytest.raises(OptionError, match="does not exist"):
        export.write_atomic(tmp_path / "missing" / "a.json", "x")
    with pytest.raises(OptionError, match="is a directory"):
        export.write_atomic(tmp_path, "x")
    assert list(tmp_path.iterdir()) == []
