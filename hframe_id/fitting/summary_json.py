"""The machine-readable summary of a fit (``hframe-id fit --json``; docs/fitting-json.md).

One JSON object, the same shape for every model::

    {"success": true, "message": "...", "model": "emps-axis", "fit_id": "...",
     "parameter_file": "fits/....yaml" or null,
     "report": "fits/...-report.md" or null (the report failed),
     "parameters": {"M": {"value": 95.1, "unit": "kg", "std": 0.8,
                          "interval_95": [93.5, 96.7], "free": true, "identified": true,
                          "initial": 95.1089}, ...},
     "channels": {"qm": {"unit": "m", "residual_rms": 1.7e-06, "noise_std": 1.7e-06}},
     "held": "..." or null,
     "initial_states": {"4V_xmotion.mcap": "rest" or "estimated"},
     "known_points": {"fit": 1904.5, "the start": 1.1e13, ...} (the simulation criterion,
                     chi^2 / 2, of the fit and the points it knows; {} if not compared),
     "starts": {"reached_best": 3, "outcomes": [{"label": "the start", "success": true,
                "criterion": 1904.5}, ...]} (a multistart portfolio, ``--starts N``; null
                without one),
     "began_from": {"label": "hframe-8-table4.1.yaml", "criteria": {"the start": -24687.3,
                    "hframe-8-table4.1.yaml": -40014.9, ...}} (where the fit began,
                    ``fitting.start_screen``: the best of the start and the model's reference
                    files by their concentrated simulation criterion from rest; criteria {}
                    where the screen did not run, with "skipped" saying why)}

Values are SI, in the parameter's ``unit``. Parameters that were not free have ``std`` and
``interval_95`` null; numbers that are not finite (an interval the data do not bound) are null.
``at_bound``: the box, not the data, stopped the parameter (its interval ends at the bound).
``open_ended``: ``"above"`` or ``"below"`` for a parameter on the widened box that the data
bound on the other side only (``fitting.open_ended``; its interval's open end is null), else
null.
A fit of several recordings that was cross-validated adds ``interval_95_jackknife`` (the
experiment-level jackknife's, ``fitting.jackknife``) to each free parameter it moved.
``information_share`` (each free parameter the statistics assessed): per recording, the
share [0-1] of the parameter's Gauss-Newton information that recording carries.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from hframe_id.fitting.known_points import KnownPointsReport
from hframe_id.fitting.multistart import StartOutcome, reached_best
from hframe_id.fitting.result import FitResult
from hframe_id.fitting.start_screen import ScreenedStart


def _number(value: float) -> float | None:
    value = float(value)
    return value if math.isfinite(value) else None


def fit_summary(
    result: FitResult, fit_id: str, parameter_file: Path | None, report: Path | None
) -> dict[str, Any]:
    """The ``--json`` object of a fit (see the module docstring)."""
    parameters = {}
    for name, est in result.estimates.items():
        parameters[name] = {
            "value": _number(est.estimate),
            "unit": est.unit,
            "std": _number(est.std_error) if est.free else None,
            "interval_95": [_number(v) for v in est.ci95] if est.free else None,
            "free": bool(est.free),
            "identified": bool(est.identified),
            "at_bound": bool(est.at_bound),
            "open_ended": est.open_ended or None,
            "initial": _number(est.initial),
        }
        if est.jackknife_ci95:
            parameters[name]["interval_95_jackknife"] = [_number(v) for v in est.jackknife_ci95]
        shares = result.statistics.information_share if result.statistics else {}
        if name in shares:
            parameters[name]["information_share"] = {
                recording: _number(share) for recording, share in shares[name].items()
            }
    units = {s.name: s.unit for s in result.problem.model.outputs} if result.problem else {}
    rms = result.diagnostics.channel_rms
    std = result.diagnostics.channel_std
    channels = {
        name: {
            "unit": units.get(name, ""),
            "residual_rms": _number(rms[name]),
            "noise_std": _number(std[name]) if name in std else None,
        }
        for name in rms
    }
    return {
        "success": bool(result.success),
        "message": result.message,
        "model": result.variant,
        "fit_id": fit_id,
        "parameter_file": str(parameter_file) if parameter_file else None,
        "report": str(report) if report else None,
        "parameters": parameters,
        "channels": channels,
        "held": result.held_statement(),
        "initial_states": {
            e.name: "rest" if e.at_rest else "estimated" for e in result.problem.experiments
        }
        if result.problem
        else {},
        "known_points": _known_points(result.diagnostics.known_points),
        "replayed_criterion": _number(result.diagnostics.known_points.replayed)
        if result.diagnostics.known_points
        else None,
        "starts": _starts(result.diagnostics.starts),
        "began_from": _began_from(result.diagnostics.start_screen),
    }


def _began_from(screen: ScreenedStart | None) -> dict[str, Any] | None:
    """Where the fit began (``start_screen.ScreenedStart``) as plain data, or None."""
    if screen is None:
        return None
    criteria = {label: _number(value) for label, value in screen.criteria.items()}
    return {"label": screen.label, "criteria": criteria, "skipped": screen.skipped or None}


def _known_points(report: KnownPointsReport | None) -> dict[str, float | None]:
    """The fit's criterion and what it was compared with, by label (the fit's: ``"fit"``;
    ``{}`` if not compared)."""
    if report is None:
        return {}
    return {label: _number(value) for label, value in report.criteria.items()}


def _starts(outcomes: tuple[StartOutcome, ...]) -> dict[str, Any] | None:
    """The portfolio's outcomes (``multistart.StartOutcome``) as plain data, or None."""
    if not outcomes:
        return None
    return {
        "reached_best": reached_best(outcomes),
        "outcomes": [
            {"label": o.label, "success": o.success, "criterion": _number(o.criterion)}
            for o in outcomes
        ],
    }
