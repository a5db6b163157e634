"""``hframe-id import`` of matrix columns: ``data(:,K)`` (MATLAB, 1-based) and ``data[:,K]``
(NumPy, 0-based) in ``--map``."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from hframe_id.cli import main
from hframe_id.recordings import read_recording
from hframe_id.recordings.matrix_columns import parse_matrix_column

N = 2000


@pytest.fixture(scope="module")
def data() -> np.ndarray:
    """A 2000 x 7 matrix as a servo's logger saves it: time, voltage, five sensors."""
    rng = np.random.default_rng(28)
    matrix = rng.normal(size=(N, 7))
    matrix[:, 0] = np.arange(N) * 1e-3
    return matrix


def run(capsys, *args) -> tuple[int, str]:
    code = main(["import", *map(str, args)])
    return code, capsys.readouterr().err


def save(path: Path, **variables) -> Path:
    scipy.io.savemat(path, variables)
    return path


COMMON = ("--variant", "rotor", "--noise-std", "w=estimate")


def test_parse_matrix_column():
    assert parse_matrix_column("data") is None
    assert parse_matrix_column("Pos (mm)") is None
    for text in ("data(:,3)", "data[:,2]", "data( : , 3 )", "data [:, 2]"):
        column = parse_matrix_column(text)
        assert (column.variable, column.index, column.problem) == ("data", 2, ""), text
    assert parse_matrix_column("data(:,0)").problem.startswith("column index '0' is not")
    assert "NumPy, 0-based" in parse_matrix_column("data[:,-1]").problem
    assert parse_matrix_column("data(:,end)").index is None


def test_columns_equal_separate_vectors(tmp_path, data, capsys):
    matrix = save(tmp_path / "servo.mat", data=data, Ts=1e-3)
    out = tmp_path / "matrix.mcap"
    code, err = run(
        capsys, matrix, "--map", "data(:,1)=time:s", "--map", "data[:,1]=input:V:u",
        "--map", "data(:,4)=output:rad/s:w", "--map", "data[:,4]=signal:A:i", *COMMON,
        "--out", out,
    )  # fmt: skip
    assert code == 0, err
    assert "rig metadata from the file: Ts" in err
    vectors = save(
        tmp_path / "vectors.mat",
        t=data[:, 0], u=data[:, 1], w=data[:, 3], i=data[:, 4], Ts=1e-3,
    )  # fmt: skip
    code, err = run(
        capsys, vectors, "--map", "t=time:s", "--map", "u=input:V", "--map", "w=output:rad/s",
        "--map", "i=signal:A", *COMMON, "--out", tmp_path / "vectors.mcap",
    )  # fmt: skip
    assert code == 0, err
    a, b = read_recording(out), read_recording(tmp_path / "vectors.mcap")
    np.testing.assert_array_equal(a.time_s, b.time_s)
    np.testing.assert_array_equal(a.inputs, b.inputs)
    np.testing.assert_array_equal(a.outputs, b.outputs)
    np.testing.assert_array_equal(a.signals, b.signals)
    np.testing.assert_array_equal(a.inputs[:, 0], data[:, 1])
    assert (a.input_names, a.output_names, a.signal_names) == (("u",), ("w",), ("i",))
    assert a.rig["Ts"] == 1e-3
    assert a.experiment["source.map"].startswith("data(:,1)=time:s data[:,1]=input:V:u")


@pytest.mark.parametrize(
    ("source", "message"),
    [
        ("data(:,8)", r"servo\.mat: data\(:,8\): column index out of range; variable 'data' is "
         r"a 2000x7 matrix, whose columns are data\(:,1\) to data\(:,7\) \(MATLAB, 1-based\) "
         r"or data\[:,0\] to data\[:,6\] \(NumPy, 0-based\)$"),
        ("data[:,7]", r"servo\.mat: data\[:,7\]: column index out of range; variable 'data' is "
         r"a 2000x7 matrix"),
        ("cells(:,1)", r"servo\.mat: variable 'cells' \(in cells\(:,1\)\) is not numeric "
         r"\(MATLAB class object\)$"),
        ("names[:,0]", r"servo\.mat: variable 'names' \(in names\[:,0\]\) is not numeric"),
        ("dta(:,2)", r"servo\.mat: dta\(:,2\): no variable 'dta'; nearest: 'data'"),
        ("data", r"servo\.mat: variable 'data' is a 2000x7 matrix, not a vector; name one of "
         r"its columns as data\(:,1\) \(MATLAB, 1-based\) or data\[:,0\] \(NumPy, 0-based\)$"),
    ],
)  # fmt: skip
def test_bad_columns_fail_in_one_line(tmp_path, data, capsys, source, message):
    cells = np.empty((N, 2), dtype=object)
    cells[:] = "x"
    matrix = save(tmp_path / "servo.mat", data=data, Ts=1e-3, cells=cells, names=["ab", "cd"])
    code, err = run(
        capsys, matrix, "--map", "data(:,2)=input:V:u", "--map", f"{source}=output:rad/s:w",
        "--sample-period", "1e-3", *COMMON, "--out", tmp_path / "o.mcap",
    )  # fmt: skip
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and re.search(message, lines[0]), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["servo.mat"]


@pytest.mark.parametrize(
    ("mapping", "message"),
    [
        ("data(:,3)=output:rad/s", r"a matrix column needs a channel NAME, e\.g\. "
         r"data\(:,3\)=output:rad/s:y"),
        ("data(:,0)=output:rad/s:w", r"column index '0' is not an integer >= 1 \(MATLAB"),
        ("data[:,-1]=output:rad/s:w", r"column index '-1' is not an integer >= 0 \(NumPy"),
    ],
)  # fmt: skip
def test_bad_column_syntax_fails_before_reading(tmp_path, data, capsys, mapping, message):
    matrix = save(tmp_path / "servo.mat", data=data)
    code, err = run(
        capsys, matrix, "--map", "data(:,2)=input:V:u", "--map", mapping,
        "--sample-period", "1e-3", *COMMON, "--out", tmp_path / "o.mcap",
    )  # fmt: skip
    assert code == 2 and len(err.strip().splitlines()) == 1 and re.search(message, err), err
