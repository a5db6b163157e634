"""Drift of each rig's parameters against its first run.

Per rig and free parameter, the baseline is the rig's earliest successful fit and the latest
its most recent one. The change is latest / baseline - 1; it is flagged when
|change| >= ``threshold`` and the 95 % interval of the difference, latest - baseline +/- 1.96
sqrt(se_latest^2 + se_baseline^2), excludes zero (the two fits' errors are independent: they
fit different recordings). A parameter not identified in either fit is never flagged.

Only fits of one model are compared: where a fit chose the larger model its job's nests in
(``fitted_model``: hframe-8-current-limit for an hframe-8 job whose records a current limit
shapes), its shared parameters are not bent around the missing limit as the smaller model's
are, so a change between the two is the structure's, not the rig's. A rig's drift is taken
over the fits of its latest fit's model, and ``structure_changes`` names the rigs whose fits
kept different models.
"""

from __future__ import annotations

import itertools
import math
import re
from dataclasses import asdict, dataclass

import pandas as pd

#: Default drift threshold: a 10 % change (belt stiffness, friction, motor gain).
DEFAULT_THRESHOLD = 0.1
Z95 = 1.959963984540054
_ESTIMATE = re.compile(r"^(?P<name>[A-Za-z_][A-Za-z0-9_]*) \[(?P<unit>[^\]]*)\]$")


@dataclass(frozen=True)
class Drift:
    """One parameter of one rig: baseline and latest estimate [SI], the relative change,
    the z score of the difference, and whether it is flagged."""

    rig: str
    parameter: str
    unit: str
    baseline: float
    latest: float
    change: float
    z: float
    runs: int
    flagged: bool

    def as_dict(self) -> dict:
        """The row as plain data (the ``--json`` shape)."""
        return asdict(self)


def parameters_of(frame: pd.DataFrame) -> list[tuple[str, str]]:
    """(name, unit) of every parameter with estimate columns in a results frame."""
    found = []
    for column in frame.columns:
        match = _ESTIMATE.match(column)
        if match and f"{match['name']} std [{match['unit']}]" in frame.columns:
            found.append((match["name"], match["unit"]))
    return found


def successful(frame: pd.DataFrame) -> pd.DataFrame:
    """The rows of converged fits, by rig and run time."""
    ok = frame[frame["status"] == "ok"]
    return ok.sort_values(["rig", "run_time"], kind="stable")


def _relative_change(baseline: float, latest: float) -> float:
    """latest / baseline - 1; a change from a baseline of zero (a friction fitted to zero)
    is infinite, or none if the latest is zero too (numpy's division warning it printed)."""
    if baseline == 0:
        return 0.0 if latest == 0 else math.copysign(math.inf, latest)
    return float(latest / baseline - 1)


def fitted_model(runs: pd.DataFrame) -> pd.Series:
    """The model each fit kept: ``fitted_model``, or the job's ``model`` in a store written
    before fits chose their structure ("" in a frame with neither)."""
    job = runs["model"] if "model" in runs else pd.Series("", index=runs.index)
    if "fitted_model" not in runs:
        return job
    return runs["fitted_model"].fillna(job)


def structure_changes(frame: pd.DataFrame) -> dict[str, list[str]]:
    """Rig -> the models its successful fits kept, in run order with repeats in a row
    collapsed (the last: the latest fit's, whose fits the drift compares), for every rig
    whose fits kept more than one."""
    changes = {}
    for rig, runs in successful(frame).groupby("rig", sort=True):
        models = [model for model, _ in itertools.groupby(fitted_model(runs))]
        if len(models) > 1:
            changes[str(rig)] = models
    return changes


def drift_table(frame: pd.DataFrame, threshold: float = DEFAULT_THRESHOLD) -> list[Drift]:
    """Every (rig, parameter) with at least two successful, identified runs of the model the
    rig's latest fit kept."""
    rows = []
    ok = successful(frame)
    for rig, runs in ok.groupby("rig", sort=True):
        kept = fitted_model(runs)
        runs = runs[kept == kept.iloc[-1]]
        for name, unit in parameters_of(ok):
            value, std = f"{name} [{unit}]", f"{name} std [{unit}]"
            identified = runs.get(f"{name} identified", pd.Series(True, index=runs.index))
            usable = runs[runs[value].notna() & identified.fillna(False).astype(bool)]
            if len(usable) < 2:
                continue
            first, last = usable.iloc[0], usable.iloc[-1]
            change = _relative_change(first[value], last[value])
            spread = math.hypot(last[std], first[std])
            difference = last[value] - first[value]
            z = difference / spread if spread > 0 else math.copysign(math.inf, difference)
            flagged = abs(change) >= threshold and abs(z) > Z95
            rows.append(
                Drift(
                    str(rig),
                    name,
                    unit,
                    float(first[value]),
                    float(last[value]),
                    float(change),
                    float(z),
                    len(usable),
                    bool(flagged),
                )
            )
    return rows
