"""Experiment-level jackknife intervals, reported next to the fit's own (issue 9).

The fit's intervals (robust sandwich / HAC, plus any held parameter's prior) describe the
noise. Under model error the estimate also depends on which experiments were fitted, and the
delete-one-recording jackknife of the leave-one-out cross-validation measures that
(``validation.cross_validation.Spread.jackknife_std``). Its interval uses Student's t with
n - 1 degrees of freedom for n converged folds (few experiments: the jackknife std is itself
uncertain; t(5) gives 2.57 for 95 %, not 1.96), in log(p) like the fit's own intervals
(relative std = jackknife std / |p|) except for signed parameters, which are p -/+ t std.
"""

from __future__ import annotations

import math
from dataclasses import replace

from hframe_id.fitting.fit import FitResult
from hframe_id.validation.cross_validation import LeaveOneOutTable


def student_t_quantile(probability: float, dof: int) -> float:
    """The ``probability`` quantile of Student's t with ``dof`` degrees of freedom."""
    from scipy.special import stdtrit  # imported here: only cross-validated fits need it

    return float(stdtrit(dof, probability))


def jackknife_interval(
    value: float, jackknife_std: float, folds: int, signed: bool, confidence: float
) -> tuple[float, float]:
    """The ``confidence`` interval of ``value`` from its jackknife std over ``folds`` (>= 2)
    folds: symmetric in log(value), or linear for a signed parameter (see the module)."""
    t = student_t_quantile(0.5 + confidence / 2, folds - 1)
    if signed or value == 0:
        return value - t * jackknife_std, value + t * jackknife_std
    factor = math.exp(min(t * jackknife_std / abs(value), 700.0))
    return value / factor, value * factor


def add_jackknife_intervals(result: FitResult, table: LeaveOneOutTable) -> None:
    """Give every free parameter with a jackknife std (two or more converged folds) its
    jackknife interval (``ParameterEstimate.jackknife_ci95``), in place."""
    folds = sum(fold.success for fold in table.folds)
    if folds < 2:
        return
    signed = {spec.name: spec.signed for spec in result.problem.model.parameters}
    confidence = result.options.confidence
    for spread in table.spread:
        est = result.estimates.get(spread.name)
        if est is None or not est.free or not math.isfinite(spread.jackknife_std):
            continue
        interval = jackknife_interval(
            est.estimate, spread.jackknife_std, folds, signed[spread.name], confidence
        )
        result.estimates[spread.name] = replace(
            est, jackknife_std=spread.jackknife_std, jackknife_ci95=interval
        )
