"""The ``--json`` object of a fit (``fitting.summary_json``, docs/fitting-json.md)."""

import dataclasses
import json
import math
from pathlib import Path

from hframe_id.fitting.known_points import KnownPointsReport
from hframe_id.fitting.multistart import StartOutcome
from hframe_id.fitting.summary_json import fit_summary


def test_every_parameter_with_its_unit_interval_and_flags(small_result):
    result = small_result()
    summary = fit_summary(result, "fit-1", Path("fits/fit-1.yaml"), None)
    assert summary["success"] is True and summary["model"] == "hframe-8"
    assert summary["parameter_file"] == "fits/fit-1.yaml" and summary["report"] is None
    k_l = summary["parameters"]["k_l"]
    assert k_l == {
        "value": 12500.0,
        "unit": "N/m",
        "std": 125.0,
        "interval_95": [12255.0, 12747.0],
        "free": True,
        "identified": True,
        "at_bound": False,
        "open_ended": None,
        "initial": 13167.0,
    }
    # Not free: no std, no interval; without a multistart or known points: null and {}.
    assert summary["parameters"]["M_cart"]["std"] is None
    assert summary["parameters"]["M_cart"]["interval_95"] is None
    assert summary["starts"] is None and summary["known_points"] == {}
    assert summary["replayed_criterion"] is None
    json.dumps(summary, allow_nan=False)  # plain JSON


def test_numbers_that_are_not_finite_are_null_and_extras_appear_when_present(small_result):
    base = small_result()
    open_ended = dataclasses.replace(
        base.estimates["k_l"],
        ci95=(0.0, math.inf),
        open_ended="above",
        jackknife_ci95=(12000.0, 13000.0),
    )
    result = small_result(estimates={**base.estimates, "k_l": open_ended}).with_diagnostics(
        starts=(StartOutcome("the start", True, 10.0), StartOutcome("draw 1", False, math.inf)),
        known_points=KnownPointsReport("chi^2 / 2", 10.0, {"the start": 12.0}),
    )
    summary = fit_summary(result, "fit-1", None, None)
    k_l = summary["parameters"]["k_l"]
    assert k_l["interval_95"] == [0.0, None] and k_l["open_ended"] == "above"
    assert k_l["interval_95_jackknife"] == [12000.0, 13000.0]
    assert summary["starts"]["reached_best"] == 1
    assert summary["starts"]["outcomes"][1] == {
        "label": "draw 1",
        "success": False,
        "criterion": None,
    }
    assert summary["known_points"] == {"fit": 10.0, "the start": 12.0}
    assert summary["replayed_criterion"] is None  # not measured: nan
    json.dumps(summary, allow_nan=False)
