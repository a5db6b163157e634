"""Experiment-level jackknife intervals, reported next to the fit's own (issue 9).

The fit's intervals (robust sandwich / HAC, plus any held parameter's prior) describe the
noise. Under model error the estimate also depends on which experiments were fitted, and the
delete-one-recording jackknife of the leave-one-out cross-validation measures that
(``validation.cross_validation.Spread.jackknife_std``). Its interval uses Student's t with
n - 1 degrees of freedom for n recordings (few experiments: the jackknife std is itself
uncertain; t(5) gives 2.57 for 95 %, not 1.96), in log(p) like the fit's own intervals
(relative std = jackknife std / |p|) except for signed parameters, which are p -/+ t std.
Only when every fold converged; folds whose parameters stopped at a bound count as converged,
and their pinned values make the spread smaller than the data alone would.
"""

from __future__ import annotations

import math
from dataclasses import replace

from hframe_id.fitting.result import FitResult, spread
from hframe_id.validation.cross_validation import LeaveOneOutTable


def student_t_quantile(probability: float, dof: int) -> float:
    """The ``probability`` quantile of Student's t with ``dof`` degrees of freedom."""
    from scipy.special import stdtrit  # imported here: only cross-validated fits need it

    return float(stdtrit(dof, probability))


def jackknife_interval(
    value: float, jackknife_std: float, folds: int, signed: bool, confidence: float
) -> tuple[float, float]:
    """The ``confidence`` interval of ``value`` (SI, non-zero unless ``signed``) from its
    jackknife std [SI] over ``folds`` (>= 2) folds: symmetric in log(value), or linear for a
    parameter fitted linearly (``signed``: ``FitProblem.linear``); ``fit.spread`` with
    Student's t for z."""
    t = student_t_quantile(0.5 + confidence / 2, folds - 1)
    theta_std = jackknife_std if signed else jackknife_std / abs(value)
    return spread(value, theta_std, signed, 1.0, t)[2]


def with_jackknife_intervals(result: FitResult, table: LeaveOneOutTable) -> FitResult:
    """``result`` with each free parameter the fit determined (not held, not at a bound)
    given its jackknife std and interval (``ParameterEstimate.jackknife_ci95``): a new
    result, ``result`` unchanged. Nothing is added unless every fold converged (a jackknife
    over the folds that did is not the delete-one jackknife of the estimate from all
    recordings) and there are two or more."""
    if len(table.folds) < 2 or not all(fold.success for fold in table.folds):
        return result
    problem = result.problem
    signed = dict(zip(problem.free_names, problem.linear.tolist(), strict=True))
    confidence = result.options.confidence
    estimates = dict(result.estimates)
    for row in table.spread:
        est = estimates.get(row.name)
        if est is None or not est.free or est.at_bound or row.name in result.not_identified:
            continue
        if not math.isfinite(row.jackknife_std):
            continue
        interval = jackknife_interval(
            est.estimate, row.jackknife_std, len(table.folds), signed[row.name], confidence
        )
        estimates[row.name] = replace(est, jackknife_std=row.jackknife_std, jackknife_ci95=interval)
    return replace(result, estimates=estimates)
