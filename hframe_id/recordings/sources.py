"""Logs from other tools, read as named numeric columns: CSV files and MATLAB .mat files.

A CSV file has one header line of column names (after any ``#`` comment lines) and one row
per sample; the delimiter (``,``, ``;`` or tab) is taken from the header. Empty cells are
missing values (NaN). A .mat file (MATLAB v4 to v7, read with ``scipy.io.loadmat``) has one
variable per column, each a vector, or matrices whose columns are named ``data(:,3)``
(MATLAB, 1-based) or ``data[:,2]`` (NumPy, 0-based); its numeric 1x1 variables are the
file's scalars (gains, constants). Every problem is a ``SourceDataError`` naming the file,
the column and the value.
"""

from __future__ import annotations

import csv
import difflib
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hframe_id.digests import sha256_file
from hframe_id.documents import not_a_file
from hframe_id.errors import HframeIdError
from hframe_id.recordings.matrix_columns import MatrixColumn, parse_matrix_column

#: Why a MATLAB v7.3 file cannot be read, and what to do.
_V73 = (
    "MATLAB v7.3 (HDF5) file, which import cannot read; save it in MATLAB with "
    "save(FILE, ..., '-v7')"
)
#: Suffixes read as CSV and as MATLAB files.
CSV_SUFFIXES = (".csv", ".tsv", ".txt")
MAT_SUFFIXES = (".mat",)


class SourceDataError(HframeIdError):
    """A file to import cannot be read, or its data are unusable (missing column, text
    where a number belongs, ragged rows, NaN runs, non-monotonic time)."""


@dataclass(frozen=True)
class SourceTable:
    """The columns of a CSV or .mat file.

    Attributes
    ----------
    path : the file.
    format : ``"csv"`` or ``"mat"``.
    raw : per column, its cells (CSV: strings) or its variable (.mat: an array).
    scalars : numeric 1x1 variables of a .mat file (Python int, float or bool).
    first_line : CSV line number (1-based) of sample 0 (None for .mat files).
    """

    path: Path
    format: str
    raw: dict[str, Any]
    scalars: dict[str, int | float | bool] = field(default_factory=dict)
    first_line: int | None = None

    def sha256(self) -> str:
        """SHA-256 of the file as hex digits (recorded as ``source.sha256``)."""
        return sha256_file(self.path)

    def at(self, i: int) -> str:
        """Sample ``i`` as a message names it (with its line in a CSV file)."""
        return (
            f"sample {i}" if self.first_line is None else f"sample {i} (line {self.first_line + i})"
        )

    def column(self, name: str) -> np.ndarray:
        """Column ``name`` as a float vector (NaN where a CSV cell is empty).

        In a .mat file, ``VAR(:,K)`` (1-based) and ``VAR[:,K]`` (0-based) name column K of
        the matrix variable ``VAR`` (``matrix_columns``); a column or variable whose name is
        literally ``name`` comes first.
        """
        matrix = parse_matrix_column(name) if self.format == "mat" else None
        if name not in self.raw and matrix is not None:
            return self._mat_matrix_column(matrix)
        if name not in self.raw:
            near = difflib.get_close_matches(name, list(self.raw), n=1)
            hint = f"; nearest: {near[0]!r}" if near else ""
            what = "column" if self.format == "csv" else "variable"
            raise SourceDataError(
                f"{self.path}: no {what} {name!r}{hint} (has: {', '.join(self.raw)})"
            )
        return self._csv_column(name) if self.format == "csv" else self._mat_column(name)

    def _csv_column(self, name: str) -> np.ndarray:
        cells = self.raw[name]
        values = np.empty(len(cells))
        for i, cell in enumerate(cells):
            text = cell.strip()
            try:
                values[i] = float(text) if text else np.nan
            except ValueError:
                raise SourceDataError(
                    f"{self.path}: column {name!r}, {self.at(i)}: {cell!r} is not a number"
                ) from None
        return values

    def _mat_numeric(self, name: str, where: str = "") -> np.ndarray:
        value = self.raw[name]
        if not isinstance(value, np.ndarray) or value.dtype.kind not in "biuf":
            kind = value.dtype.name if isinstance(value, np.ndarray) else type(value).__name__
            raise SourceDataError(
                f"{self.path}: variable {name!r}{where} is not numeric (MATLAB class {kind})"
            )
        return value

    def _mat_column(self, name: str) -> np.ndarray:
        value = self._mat_numeric(name)
        if value.ndim > 2 or min(value.shape, default=0) > 1:
            shape = "x".join(str(n) for n in value.shape)
            raise SourceDataError(
                f"{self.path}: variable {name!r} is a {shape} matrix, not a vector; name one "
                f"of its columns as {name}(:,1) (MATLAB, 1-based) or {name}[:,0] (NumPy, "
                "0-based)"
            )
        return value.astype(float).ravel()

    def _mat_matrix_column(self, matrix: MatrixColumn) -> np.ndarray:
        name, text = matrix.variable, matrix.text
        if matrix.index is None:
            raise SourceDataError(f"{self.path}: {text}: {matrix.problem}")
        if name not in self.raw:
            near = difflib.get_close_matches(name, list(self.raw), n=1)
            hint = f"; nearest: {near[0]!r}" if near else ""
            raise SourceDataError(
                f"{self.path}: {text}: no variable {name!r}{hint} (has: {', '.join(self.raw)})"
            )
        value = self._mat_numeric(name, f" (in {text})")
        shape = "x".join(str(n) for n in value.shape)
        if value.ndim != 2:
            raise SourceDataError(
                f"{self.path}: {text}: variable {name!r} is a {shape} array, not a matrix"
            )
        if matrix.index >= value.shape[1]:
            raise SourceDataError(
                f"{self.path}: {text}: column index out of range; variable {name!r} is a "
                f"{shape} matrix, whose {matrix.describe_range(value.shape[1])}"
            )
        return value[:, matrix.index].astype(float)


def read_source(path: str | os.PathLike) -> SourceTable:
    """Read a CSV (``.csv``, ``.tsv``, ``.txt``) or MATLAB (``.mat``) file."""
    path = Path(path)
    if not path.is_file():
        raise SourceDataError(f"{path}: {not_a_file(path)}")
    suffix = path.suffix.lower()
    if suffix in CSV_SUFFIXES:
        return _read_csv(path)
    if suffix in MAT_SUFFIXES:
        return _read_mat(path)
    raise SourceDataError(
        f"{path}: unknown file type {path.suffix!r}; import reads CSV "
        f"({', '.join(CSV_SUFFIXES)}) and MATLAB ({', '.join(MAT_SUFFIXES)}) files"
    )


def _read_csv(path: Path) -> SourceTable:
    with open(path, "rb") as stream:
        if b"\0" in stream.read(65536):
            raise SourceDataError(f"{path}: binary data, not a CSV text file")
    try:
        lines = path.read_text(encoding="utf-8-sig").splitlines()
    except UnicodeDecodeError as err:
        raise SourceDataError(f"{path}: not a UTF-8 text file ({err.reason})") from None
    start = 0
    while start < len(lines) and (not lines[start].strip() or lines[start].startswith("#")):
        start += 1
    if start == len(lines):
        raise SourceDataError(f"{path}: no header line (the file is empty or all comments)")
    try:
        delimiter = csv.Sniffer().sniff(lines[start][:4096], delimiters=",;\t").delimiter
    except csv.Error:
        delimiter = ","
    try:
        # row by row in Python, not list(): one C call over millions of rows holds the GIL
        # and delays Ctrl-C for seconds
        rows = [row for row in csv.reader(lines[start:], delimiter=delimiter)]
    except csv.Error as err:
        raise SourceDataError(f"{path}: not a readable CSV file ({err})") from None
    header = [name.strip() for name in rows[0]]
    doubled = sorted({n for n in header if header.count(n) > 1})
    if doubled or "" in header:
        what = f"column(s) {', '.join(map(repr, doubled))} twice" if doubled else "an empty name"
        raise SourceDataError(f"{path}: line {start + 1}: the header has {what}")
    body = rows[1:]
    while body and not any(cell.strip() for cell in body[-1]):
        body.pop()
    for i, row in enumerate(body):
        if len(row) != len(header):
            raise SourceDataError(
                f"{path}: line {start + 2 + i} has {len(row)} field(s), the header has "
                f"{len(header)}"
            )
    if not body:
        raise SourceDataError(f"{path}: no data rows after the header")
    raw = {name: [row[j] for row in body] for j, name in enumerate(header)}
    return SourceTable(path=path, format="csv", raw=raw, first_line=start + 2)


def _read_mat(path: Path) -> SourceTable:
    import scipy.io

    with open(path, "rb") as stream:
        head = stream.read(128)
    if head.startswith(b"MATLAB 7.3") or head.startswith(b"\x89HDF"):
        raise SourceDataError(f"{path}: {_V73}")
    try:
        variables = scipy.io.loadmat(path)
    except NotImplementedError:  # scipy's answer to a v7.3 file
        raise SourceDataError(f"{path}: {_V73}") from None
    except Exception as err:  # scipy on a corrupt file: any error (an IndexError when cut)
        reason = f"{type(err).__name__}: {err}" if str(err) else type(err).__name__
        raise SourceDataError(f"{path}: not a readable MATLAB .mat file ({reason})") from None
    raw = {k: v for k, v in variables.items() if not k.startswith("__")}
    scalars = {
        k: v.item()
        for k, v in raw.items()
        if isinstance(v, np.ndarray) and v.dtype.kind in "biuf" and v.size == 1
    }
    return SourceTable(path=path, format="mat", raw=raw, scalars=scalars)
