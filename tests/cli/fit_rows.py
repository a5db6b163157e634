"""Results stores of fits for the ``fleet report`` tests: rows as ``batch`` stores them."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path

from hframe_id.fleet.store import ResultsStore


def stored_fits(path: Path, rows: list[tuple[str, str, datetime, float]]) -> Path:
    """A results store at ``path`` of successful fits, one per (key, rig, run time, k_l
    [N/m]), each k_l with a std of 10 N/m and a 95 % interval of +/-20 N/m."""
    store = ResultsStore(path)
    for key, rig, run_time, value in rows:
        store.add(
            {
                "key": key,
                "rig": rig,
                "run_time": run_time,
                "status": "ok",
                "message": "",
                "k_l [N/m]": value,
                "k_l std [N/m]": 10.0,
                "k_l ci95 low [N/m]": value - 20,
                "k_l ci95 high [N/m]": value + 20,
                "k_l identified": True,
            }
        )
    store.flush()
    return path
