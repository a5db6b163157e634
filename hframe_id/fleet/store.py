"""The results store: one Parquet row per fit, rewritten atomically.

Columns (``docs/fleet.md``): ``key`` (sha256 of the recordings' sha256, model, initial file
and fit options; the store holds one row per key), ``rig``, ``run_time`` (UTC),
``recordings`` / ``recordings_sha256`` (``;``-separated), ``status`` (``ok``, ``failed``,
``error``), ``message``, ``fit_id``, ``parameter_file``, ``report``, per free parameter
``NAME [UNIT]``, ``NAME std [UNIT]``, ``NAME ci95 low [UNIT]``, ``NAME ci95 high [UNIT]``,
``NAME identified``, per channel ``rms CHANNEL [UNIT]``, ``residual_rms [noise std]``,
``wall_time [s]`` (on the worker, reading to files written), ``fit_time [s]`` (the solver),
``worker`` and ``stored_at`` (UTC).

Every write goes to a temporary file in the same folder renamed over the store
(``os.replace``), so a reader, a crash or Ctrl-C never sees half a file.
"""

from __future__ import annotations

import datetime as dt
import io
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from hframe_id.atomic import replace_atomically
from hframe_id.errors import HframeIdError, shown


class StoreError(HframeIdError):
    """The results file cannot be read or written."""


class ResultsStore:
    """Rows of a Parquet results file, in memory, written back with ``flush``.

    Parameters
    ----------
    path : the ``.parquet`` file (created by the first ``flush`` if absent).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.rows: dict[str, dict[str, Any]] = {}
        self._dirty = False
        if self.path.exists():
            for row in read_results(self.path).to_dict("records"):
                self.rows[row["key"]] = row

    def __contains__(self, key: str) -> bool:
        return key in self.rows

    def __len__(self) -> int:
        return len(self.rows)

    def add(self, row: dict[str, Any]) -> None:
        """Add or replace the row of ``row["key"]`` (written by the next ``flush``)."""
        self.rows[row["key"]] = {**row, "stored_at": dt.datetime.now(dt.UTC)}
        self._dirty = True

    def frame(self) -> pd.DataFrame:
        """Every row, ordered by rig and run time."""
        frame = pd.DataFrame(list(self.rows.values()))
        if frame.empty:
            return frame
        return frame.sort_values(["rig", "run_time"], kind="stable").reset_index(drop=True)

    def flush(self) -> None:
        """Write every row to ``path`` atomically (nothing if no row changed)."""
        if not self._dirty:
            return
        buffer = io.BytesIO()
        pq.write_table(pa.Table.from_pandas(self.frame(), preserve_index=False), buffer)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            replace_atomically(self.path, buffer.getvalue())
        except OSError as err:
            raise StoreError(f"{self.path}: cannot write the results ({err})") from err
        self._dirty = False


def read_results(path: str | Path) -> pd.DataFrame:
    """The rows of a results file (``StoreError`` if it is not one)."""
    path = Path(path)
    try:
        frame = pq.read_table(path).to_pandas()
    except (OSError, pa.ArrowException) as err:
        raise StoreError(f"{path}: not a readable Parquet results file ({err})") from None
    missing = [c for c in ("key", "rig", "run_time", "status") if c not in frame.columns]
    if missing:
        raise StoreError(f"{path}: not a results file (no column {missing[0]!r})")
    for column in frame.columns:
        problem = _column_problem(frame, column)
        if problem:
            raise StoreError(f"{path}: not a results file (column {column!r} {problem})")
    return frame


#: The values of the ``status`` column.
STATUSES = ("ok", "failed", "error")


def _column_problem(frame: pd.DataFrame, column: str) -> str | None:
    """What is wrong with the values of ``column`` for its kind (the module docstring's
    columns: text, a time with a zone, the status, a flag, a number with its unit), or None.
    A store edited or written by another program used to give a traceback or a report of
    nonsense."""
    values = frame[column]
    if column in ("key", "rig", "status"):
        if not values.map(lambda value: isinstance(value, str)).all():
            return "must hold text"
        unknown = sorted(set(values) - set(STATUSES)) if column == "status" else []
        return f"holds {shown(unknown[0])}, not one of {', '.join(STATUSES)}" if unknown else None
    if column == "run_time":
        zoned = isinstance(values.dtype, pd.DatetimeTZDtype)
        return None if zoned else "must hold times with a time zone"
    if column.endswith(" identified"):  # empty in the rows of failed fits
        flags = values.dropna().map(lambda value: isinstance(value, bool | np.bool_)).all()
        return None if flags else "must hold true or false"
    if column.endswith("]"):  # NAME [UNIT], NAME std [UNIT], rms CHANNEL [UNIT], wall_time [s]
        numbers = pd.api.types.is_numeric_dtype(values) and not pd.api.types.is_bool_dtype(values)
        if not numbers:
            return "must hold numbers"
        if np.isinf(values.to_numpy(dtype=float)).any():
            return "holds an infinite value"
    return None
