"""Drift of each rig's parameters against its first run.

Per rig and free parameter, the baseline is the rig's earliest successful fit and the latest
its most recent one. The change is latest / baseline - 1; it is flagged when
|change| >= ``threshold`` and the 95 % interval of the difference, latest - baseline +/- 1.96
sqrt(se_latest^2 + se_baseline^2), excludes zero (the two fits' errors are independent: they
fit different recordings). A parameter not identified in either fit is never flagged.

Under model mismatch those standard errors understate how far a healthy rig's estimate moves
from week to week: each week's records pull a mismatched model's parameters their own way
(realistic fleet, seed 7: an unaged rig's k_l 29,760, 39,570 and 21,260 N/m with 4-6 %
standard errors). So a change must also stand out against the fleet's own scatter
(``fleet_scatter``): the robust standard deviation of the week-to-week log-changes of the
parameter on the *other* rigs (a rig's own aging must not widen its own yardstick; their
fits of the model each rig's latest kept, identified or not: a poorly determined estimate
scatters, and that is what is measured), sigma = 1.4826 median |ln(theta_w+1 / theta_w)| /
sqrt(2) (a healthy week's estimate is off by sigma, a difference of two by sqrt(2) sigma; the
median, as a few other rigs may have aged on it too). The change is flagged only if also
z_scatter = ln(latest / baseline) / (sqrt(2) sigma) stands out at 95 %: |z_scatter| > c, the
critical value of that statistic for the estimate of sigma actually used
(``scatter_critical_value``). sigma comes from a handful of changes (four rigs over three
weeks: six, two per rig and each pair sharing a week), so c is not 1.96, which holds for a
known sigma: it is the 95 % quantile of |z_scatter| over draws of a healthy fleet (every
estimate an independent normal, the other rigs' changes formed as for the data): 2.67 for
three other rigs of three runs, 2.24 for seven of four, 1.97 for fifty of 52. Without other
rigs' changes (one rig, or estimates that are not all positive: a friction fitted to zero) or
with a baseline or latest value <= 0, only the first test applies.

Only fits of one model are compared: where a fit chose the larger model its job's nests in
(``fitted_model``: hframe-8-current-limit for an hframe-8 job whose records a current limit
shapes), its shared parameters are not bent around the missing limit as the smaller model's
are, so a change between the two is the structure's, not the rig's. A rig's drift is taken
over the fits of its latest fit's model, and ``structure_changes`` names the rigs whose fits
kept different models.
"""

from __future__ import annotations

import functools
import itertools
import math
import re
from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd

#: Default drift threshold: a 10 % change (belt stiffness, friction, motor gain).
DEFAULT_THRESHOLD = 0.1
Z95 = 1.959963984540054
#: A normal sample's std over its median absolute deviation from 0 (1 / Phi^-1(3/4)).
MAD_TO_STD = 1.4826
#: Draws of a healthy fleet that set the scatter test's critical value, and their seed: the
#: quantile's Monte Carlo error is then about 1 % (binomial, 95 % quantile).
NULL_DRAWS = 20_000
NULL_SEED = 20070501
#: Largest draws x changes array formed at once (8 bytes each).
NULL_CHUNK = 2_000_000
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
    #: the other rigs' week-to-week relative scatter sigma (``fleet_scatter``; nan: none)
    scatter: float = math.nan
    #: ln(latest / baseline) / (sqrt(2) sigma) (nan without a scatter)
    z_scatter: float = math.nan
    #: the 95 % critical value of |z_scatter| (``scatter_critical_value``; nan: none)
    scatter_critical: float = math.nan

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


def compared_runs(frame: pd.DataFrame) -> dict[str, tuple[str, pd.DataFrame]]:
    """Rig -> (the model its latest fit kept, its successful fits of that model)."""
    compared = {}
    for rig, runs in successful(frame).groupby("rig", sort=True):
        kept = fitted_model(runs)
        compared[str(rig)] = (kept.iloc[-1], runs[kept == kept.iloc[-1]])
    return compared


def usable_values(runs: pd.DataFrame, name: str, unit: str) -> pd.DataFrame:
    """The runs whose fit estimated and identified ``name``."""
    value = f"{name} [{unit}]"
    identified = runs.get(f"{name} identified", pd.Series(True, index=runs.index))
    return runs[runs[value].notna() & identified.fillna(False).astype(bool)]


def week_to_week_log_changes(values: pd.Series) -> list[float]:
    """ln(theta_w+1 / theta_w) between a rig's successive estimates, where both are > 0."""
    v = values.to_numpy(dtype=float)
    return [math.log(b / a) for a, b in itertools.pairwise(v) if a > 0 and b > 0]


def positive_runs(values: pd.Series) -> tuple[bool, ...]:
    """Per run, whether its estimate is > 0: the runs ``week_to_week_log_changes`` pairs."""
    return tuple(bool(v > 0) for v in values.to_numpy(dtype=float))


@functools.lru_cache(maxsize=256)
def scatter_critical_value(others: tuple[tuple[bool, ...], ...], confidence: float = 0.95) -> float:
    """The critical value c of |z_scatter| at ``confidence`` (module docstring) for other rigs
    whose runs are ``others`` (per rig, ``positive_runs``, sorted: rigs are exchangeable).

    Under a healthy fleet every estimate is its rig's value times exp(sigma e), e independent
    standard normal. The statistic is scale-free, so sigma = 1: per draw, the other rigs'
    week-to-week changes e_w+1 - e_w (where both runs are positive, as in the data), the
    judged rig's change e_latest - e_baseline (two independent estimates), and
    |e_latest - e_baseline| / (1.4826 median |e_w+1 - e_w|); c is the ``confidence`` quantile
    over ``NULL_DRAWS`` draws (``default_rng(NULL_SEED)``). inf without any change.
    """
    pairs = [
        (start + w, start + w + 1)
        for start, runs in zip(
            itertools.accumulate((len(r) for r in others), initial=0), others, strict=False
        )
        for w, (a, b) in enumerate(itertools.pairwise(runs))
        if a and b
    ]
    if not pairs:
        return math.inf
    first, second = (np.array(p) for p in zip(*pairs, strict=True))
    n_runs = sum(len(r) for r in others)
    rng = np.random.default_rng(NULL_SEED)
    statistics = []
    chunk = max(1, NULL_CHUNK // n_runs)
    for done in range(0, NULL_DRAWS, chunk):
        e = rng.standard_normal((min(chunk, NULL_DRAWS - done), n_runs))
        scale = MAD_TO_STD * np.median(np.abs(e[:, second] - e[:, first]), axis=1)
        judged = np.abs(rng.standard_normal(e.shape[0]) - rng.standard_normal(e.shape[0]))
        statistics.append(judged / scale)
    return float(np.quantile(np.concatenate(statistics), confidence))


def fleet_scatter(changes_of_other_rigs: list[float]) -> float:
    """A healthy estimate's relative scatter sigma from week-to-week log-changes (module
    docstring): 1.4826 median |d| / sqrt(2); nan without any."""
    if not changes_of_other_rigs:
        return math.nan
    return MAD_TO_STD * float(np.median(np.abs(changes_of_other_rigs))) / math.sqrt(2)


def drift_table(frame: pd.DataFrame, threshold: float = DEFAULT_THRESHOLD) -> list[Drift]:
    """Every (rig, parameter) with at least two successful, identified runs of the model the
    rig's latest fit kept."""
    rows = []
    compared = compared_runs(frame)
    for name, unit in parameters_of(successful(frame)):
        value, std = f"{name} [{unit}]", f"{name} std [{unit}]"
        usable = {rig: usable_values(runs, name, unit) for rig, (_, runs) in compared.items()}
        log_changes = {
            rig: week_to_week_log_changes(runs[value]) for rig, (_, runs) in compared.items()
        }
        positive = {rig: positive_runs(runs[value]) for rig, (_, runs) in compared.items()}
        for rig, runs in usable.items():
            if len(runs) < 2:
                continue
            others = [d for other, ds in log_changes.items() if other != rig for d in ds]
            critical = scatter_critical_value(
                tuple(sorted(p for other, p in positive.items() if other != rig))
            )
            fleet = (fleet_scatter(others), critical)
            rows.append(_drift(rig, name, unit, runs[value], runs[std], fleet, threshold))
    return sorted(rows, key=lambda d: d.rig)


def _drift(rig, name, unit, values, stds, fleet: tuple[float, float], threshold: float) -> Drift:
    """The baseline (first) and latest (last) of a rig's ``values`` judged (module docstring);
    ``fleet``: the fleet's scatter sigma and the critical value of its test."""
    scatter, critical = fleet
    first, last = float(values.iloc[0]), float(values.iloc[-1])
    change = _relative_change(first, last)
    spread = math.hypot(float(stds.iloc[-1]), float(stds.iloc[0]))
    difference = last - first
    z = difference / spread if spread > 0 else math.copysign(math.inf, difference)
    z_scatter = math.nan
    if scatter > 0 and first > 0 and last > 0:
        z_scatter = math.log(last / first) / (math.sqrt(2) * scatter)
    # nan (no scatter to judge against) leaves the decision to the first two tests
    flagged = abs(change) >= threshold and abs(z) > Z95 and not abs(z_scatter) <= critical
    return Drift(
        rig,
        name,
        unit,
        first,
        last,
        float(change),
        float(z),
        len(values),
        bool(flagged),
        scatter,
        z_scatter,
        critical if math.isfinite(z_scatter) else math.nan,
    )
