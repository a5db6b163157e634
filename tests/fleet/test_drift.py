"""Drift flags over a results frame (hframe_id.fleet.drift): fits of one model compared only."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from hframe_id.fleet.drift import (
    Z95,
    drift_table,
    fleet_scatter,
    scatter_critical_value,
    structure_changes,
    week_to_week_log_changes,
)
from hframe_id.fleet.report import structure_lines

LIMITED = "hframe-8-current-limit"


def _row(rig: str, week: int, model: str, fitted: str | None, k_l: float, status: str = "ok"):
    row = {
        "rig": rig,
        "run_time": pd.Timestamp("2026-01-05", tz="UTC") + pd.Timedelta(weeks=week),
        "model": model,
        "status": status,
        "k_l [N/m]": k_l,
        "k_l std [N/m]": 0.01 * k_l,  # 1 %: any 10 % change is significant
        "k_l identified": True,
    }
    if fitted is not None:
        row["fitted_model"] = fitted
    return row


def test_drift_is_judged_over_the_fits_of_the_latest_fits_model():
    # rig-01: hframe-8 bent its belt around a missing current limit in week 0 (k_l 70),
    # the limited model in weeks 1-2 holds the rig's unchanged 100: no drift, not -30 %.
    frame = pd.DataFrame(
        [
            _row("rig-01", 0, "hframe-8", "hframe-8", 70.0),
            _row("rig-01", 1, "hframe-8", LIMITED, 100.0),
            _row("rig-01", 2, "hframe-8", LIMITED, 101.0),
            _row("rig-02", 0, "hframe-8", "hframe-8", 100.0),
            _row("rig-02", 2, "hframe-8", "hframe-8", 70.0),
        ]
    )
    drifts = {(d.rig, d.parameter): d for d in drift_table(frame)}
    assert drifts["rig-01", "k_l"].baseline == 100.0
    assert drifts["rig-01", "k_l"].runs == 2
    assert not drifts["rig-01", "k_l"].flagged
    assert drifts["rig-02", "k_l"].flagged  # one model throughout: judged as before
    assert structure_changes(frame) == {"rig-01": ["hframe-8", LIMITED]}
    (line,) = structure_lines(structure_changes(frame))
    assert line.startswith("rig-01: its fits kept hframe-8 then hframe-8-current-limit")


def test_a_rig_with_one_fit_of_its_latest_model_is_not_judged():
    frame = pd.DataFrame(
        [
            _row("rig-01", 0, "hframe-8", "hframe-8", 100.0),
            _row("rig-01", 1, "hframe-8", LIMITED, 70.0),
        ]
    )
    assert drift_table(frame) == []


@pytest.mark.parametrize("with_column", [False, True])
def test_a_store_without_the_fitted_model_compares_the_jobs_model(with_column):
    # A store written before fits chose their structure has no ``fitted_model``; a failed
    # row of a newer one has it empty.
    rows = [_row("rig-01", 0, "hframe-8", None, 100.0), _row("rig-01", 1, "hframe-8", None, 70.0)]
    frame = pd.DataFrame(rows)
    if with_column:
        frame["fitted_model"] = [None, "hframe-8"]
    (drift,) = drift_table(frame)
    assert drift.flagged and drift.change == pytest.approx(-0.3)
    assert structure_changes(frame) == {}


def test_a_rig_back_on_its_first_model_is_judged_over_that_models_fits():
    """hframe-8, then the limited model, then hframe-8 again: the drift compares the two
    hframe-8 fits, and the structure line ends with hframe-8 (the latest fit's model)."""
    frame = pd.DataFrame(
        [
            _row("rig-01", 0, "hframe-8", "hframe-8", 100.0),
            _row("rig-01", 1, "hframe-8", LIMITED, 60.0),
            _row("rig-01", 2, "hframe-8", "hframe-8", 101.0),
        ]
    )
    (drift,) = drift_table(frame)
    assert (drift.baseline, drift.latest, drift.runs) == (100.0, 101.0, 2)
    assert structure_changes(frame) == {"rig-01": ["hframe-8", LIMITED, "hframe-8"]}
    (line,) = structure_lines(structure_changes(frame))
    assert line.endswith("drift is judged over its hframe-8 fits only")


def _history(rig: str, values: list[float], std: float = 0.01) -> list[dict]:
    rows = []
    for week, k_l in enumerate(values):
        row = _row(rig, week, "hframe-8", "hframe-8", k_l)
        row["k_l std [N/m]"] = std * k_l
        rows.append(row)
    return rows


def _drifts(k_l_by_rig: dict[str, list[float]]) -> dict:
    """Rig -> its k_l drift, each rig's weekly estimates given with 1 % standard errors."""
    rows = [row for rig, values in k_l_by_rig.items() for row in _history(rig, values)]
    return {d.rig: d for d in drift_table(pd.DataFrame(rows))}


def test_fleet_scatter_is_a_robust_std_of_one_estimate():
    # |d| = 0.1, 0.1, 0.1, 0.1, 5 (one rig on another optimum): median 0.1; a difference
    # of two healthy estimates has sqrt(2) sigma.
    assert fleet_scatter([0.1, -0.1, 0.1, -0.1, 5.0]) == pytest.approx(1.4826 * 0.1 / math.sqrt(2))
    assert math.isnan(fleet_scatter([]))
    assert week_to_week_log_changes(pd.Series([100.0, 0.0, 50.0, 100.0])) == pytest.approx(
        [math.log(2.0)]
    )


def test_a_change_within_the_fleets_week_to_week_scatter_is_not_flagged():
    # Every rig's estimate moves +/-30 % between weeks with 1 % standard errors (fits of a
    # mismatched model landing on other optima): rig-01's -28 % is not drift.
    drifts = _drifts(
        {
            "rig-01": [100.0, 130.0, 72.0],
            "rig-02": [100.0, 70.0, 100.0],
            "rig-03": [100.0, 135.0, 95.0],
        }
    )
    assert abs(drifts["rig-01"].z) > 1.96  # the standard errors alone would flag it
    assert drifts["rig-01"].scatter > 0.2
    assert not any(d.flagged for d in drifts.values())


def test_a_rigs_own_aging_does_not_widen_its_yardstick():
    # rig-03 ages 15 % a week; the healthy rigs scatter by 1 %: only rig-03 is flagged,
    # its scatter from rig-01 and rig-02 alone.
    drifts = _drifts(
        {
            "rig-01": [100.0, 101.0, 99.5],
            "rig-02": [100.0, 99.0, 100.5],
            "rig-03": [100.0, 85.0, 70.0],
        }
    )
    assert [rig for rig, d in drifts.items() if d.flagged] == ["rig-03"]
    assert drifts["rig-03"].scatter < 0.02
    assert drifts["rig-03"].z_scatter < -1.96


def test_without_other_rigs_the_interval_alone_decides():
    (drift,) = drift_table(pd.DataFrame(_history("rig-01", [100.0, 70.0])))
    assert math.isnan(drift.scatter) and drift.flagged


def test_the_scatter_tests_critical_value_is_that_of_its_estimated_sigma():
    # Many changes: sigma is known, the normal 1.96 (the Monte Carlo quantile of 20,000
    # draws is within about 1 %); a few: larger, and larger the fewer they are.
    many = scatter_critical_value(((True,) * 52,) * 50)
    assert many == pytest.approx(Z95, rel=0.02)
    three_rigs = scatter_critical_value(((True,) * 3,) * 3)
    assert Z95 * 1.2 < three_rigs < scatter_critical_value(((True,) * 3,) * 2)
    # A run whose estimate is not positive breaks its two changes, as in the data.
    gap = scatter_critical_value(((True, False, True), (True,) * 3, (True,) * 3))
    assert gap > three_rigs
    assert scatter_critical_value(((True,),)) == math.inf


def test_a_change_past_196_but_within_the_critical_value_is_not_flagged():
    # Three healthy rigs scatter +/-10 % between weeks; rig-04 moves -28 %: z_scatter
    # ln(0.72) / (1.4826 x 0.0953) = -2.32 against sigma from six changes, past 1.96, not
    # past their critical value (2.67).
    drifts = _drifts(
        {
            "rig-01": [100.0, 110.0, 100.0],
            "rig-02": [100.0, 90.0, 100.0],
            "rig-03": [100.0, 110.0, 100.0],
            "rig-04": [100.0, 95.0, 72.0],
        }
    )
    rig4 = drifts["rig-04"]
    assert -rig4.scatter_critical < rig4.z_scatter < -Z95
    assert not rig4.flagged
