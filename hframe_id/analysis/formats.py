"""The formats of ``hframe-id export``: names, kinds and descriptions, without the code that
writes them (``hframe_id.analysis.export``), so that ``export --help`` imports nothing heavy."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ExportFormat:
    """One ``hframe-id export`` format.

    ``kind`` is ``"parameters"`` or ``"statespace"``; ``binary`` formats need an output file.
    """

    name: str
    kind: str
    binary: bool
    suffix: str
    description: str


FORMATS: dict[str, ExportFormat] = {
    f.name: f
    for f in (
        ExportFormat("json", "parameters", False, ".json", "parameters: name, unit, value (JSON)"),
        ExportFormat("csv", "parameters", False, ".csv", "parameters: name,unit,value,description"),
        ExportFormat(
            "statespace", "statespace", False, ".json", "A, B, C, D with names and units (JSON)"
        ),
        ExportFormat("matlab", "statespace", True, ".mat", "MAT-file: A, B, C, D, names, units"),
        ExportFormat(
            "matlab-script", "statespace", False, ".m", "MATLAB script building sys = ss(...)"
        ),
        ExportFormat(
            "python-control",
            "statespace",
            False,
            ".py",
            "Python module whose ss() returns a python-control StateSpace",
        ),
    )
}
