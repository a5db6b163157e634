"""From a solver's end point to a ``FitResult``: estimates, intervals, the box's verdict."""

from __future__ import annotations

import math
import time
from dataclasses import replace

from hframe_id.fitting.link_options import StatisticsOptions
from hframe_id.fitting.noise_rounds import channel_rms
from hframe_id.fitting.options import FitOptions
from hframe_id.fitting.result import FitDiagnostics, FitResult, ParameterEstimate, spread
from hframe_id.parameters import ParameterSet

#: A free parameter closer to a bound than this many of its (relative) standard errors is
#: "at the bound": the bound, not the data, fixes it. Exactly on the bound is not required:
#: under mismatch a parameter running into its bound stopped 2e-4 (relative) short of it
#: when the stage ended on its cost criterion, and was reported converged while a fit with
#: the same parameter 1e-9 closer was reported at the bound. Such a fit still succeeds when
#: its solver converged (issue 9: a failure is a solver that did not converge): the box is
#: part of the problem, and the parameters it stopped are named in the message, the report
#: and the parameter file (``at_bound``), their intervals ending at the bound.
AT_BOUND_STD = 0.1


def at_bound_clause(names: list[str]) -> str:
    """The clause of a fit's message naming the parameters a bound stopped ("" if none)."""
    if not names:
        return ""
    return (
        f"; at a bound (the box, not the data, ends them there; their intervals stop at it; "
        f"--bounds widens it): {', '.join(names)}"
    )


def is_at_bound(theta: float, lower: float, upper: float, relative_std: float) -> bool:
    """Whether a free parameter (``theta`` between its bounds, theta units) is at a bound:
    within ``AT_BOUND_STD`` of its relative standard error (at most 1) of it, or 1e-9."""
    near = 1e-9 + AT_BOUND_STD * min(relative_std, 1.0)
    return theta <= lower + near or theta >= upper - near


def ended_at_bound(problem, state, f: int, ci95: tuple[float, float]) -> tuple[float, float]:
    """The interval of free parameter ``f`` (at a bound) cut at that bound [SI]: the box
    allowed no values beyond it."""
    lower = state.theta[f] - problem.theta_lower[f] < problem.theta_upper[f] - state.theta[f]
    theta = state.theta.copy()
    theta[f] = problem.theta_lower[f] if lower else problem.theta_upper[f]
    bound = float(problem.parameters(theta)[problem.free[f]])
    return (bound, max(ci95[1], bound)) if lower else (min(ci95[0], bound), bound)


def parameter_estimates(
    problem, state, stats, held, options: StatisticsOptions
) -> tuple[dict, list[str], list[str]]:
    """Every parameter's estimate at ``state`` [SI], its standard error and interval from
    ``stats`` (or, for a parameter held for identifiability, from ``held``: name ->
    (relative std, Gauss-Newton relative std, collinearity) when it was found out), at the
    ``options``' confidence and identifiability threshold; and the free parameters at a
    bound, and those among them on the default box."""
    p = problem.parameters(state.theta)
    names = problem.model.parameter_names
    specs = {s.name: s for s in problem.model.parameters}
    z = stats.z_value(options.confidence)
    estimates: dict[str, ParameterEstimate] = {}
    at_bound, at_box = [], []
    active_names = stats.names
    for i, name in enumerate(names):
        spec = specs[name]
        value = float(p[i])
        initial_value = float(problem.p_initial[i])
        if i not in problem.free:
            estimates[name] = ParameterEstimate(
                name, spec.unit, initial_value, value, 0.0, (value, value), False, False
            )
            continue
        f = problem.free.index(i)
        if name in active_names:
            k = active_names.index(name)
            rel, rel_gn, col = (
                float(stats.relative_std[k]),
                float(stats.relative_std_gn[k]),
                float(stats.collinearity[k]),
            )
            identified = rel <= options.identifiability_threshold
        else:
            rel, rel_gn, col = held.get(name, (math.inf, math.inf, math.inf))
            identified = False
        bound = bool(state.active[f]) and is_at_bound(
            state.theta[f], problem.theta_lower[f], problem.theta_upper[f], rel
        )
        # At zero (its lower bound, also from a start at 0): physics ends it there, not the box.
        lower = state.theta[f] - problem.theta_lower[f] < problem.theta_upper[f] - state.theta[f]
        floor = problem.zero_floor[f] and lower
        if bound and floor:
            bound = False
        if bound:  # the box, not the data, fixes it
            at_bound.append(name)
            identified = False
            if problem.on_box(state.theta)[f]:
                at_box.append(name)
        std, rel, ci95 = spread(value, rel, problem.linear[f], problem.linear_scale[f], z)
        if bound:
            ci95 = ended_at_bound(problem, state, f, ci95)
        elif problem.zero_floor[f]:
            ci95 = (max(ci95[0], 0.0), ci95[1])
        estimates[name] = ParameterEstimate(
            name=name,
            unit=spec.unit,
            initial=initial_value,
            estimate=value,
            std_error=std,
            ci95=ci95,
            identified=identified,
            free=True,
            relative_std=rel,
            relative_std_gn=rel_gn,
            collinearity=col,
            at_bound=bound,
        )
    return estimates, at_bound, at_box


def fit_result(
    problem, options: FitOptions, ms, gn, state, stages, stats, held, start, regression=None
) -> FitResult:
    """The ``FitResult`` of a solve of ``problem`` with ``options`` (the fit's, kept as
    ``FitResult.options``) that ended at ``state`` after ``stages``; ``held``: the
    parameters held for identifiability (``parameter_estimates``), ``start`` the
    ``time.perf_counter()`` the fit began at, ``regression`` the equation-error estimate's
    (theta, seconds) or None."""
    final = stages[-1]
    p = problem.parameters(state.theta)
    names = problem.model.parameter_names
    estimates, at_bound, at_box = parameter_estimates(
        problem, state, stats, held, options.statistics_options
    )
    not_identified = tuple(n for n in problem.free_names if n in held)
    if not_identified:
        # Imported here: the standard designs read the shipped datasets' protocols (0.15 s).
        from hframe_id.fitting.design_advice import identifying_designs

        advice = identifying_designs(
            problem, ms, gn, state, stats, not_identified, options.identifiability_threshold
        )
        for name, designs in advice.items():
            estimates[name] = replace(estimates[name], identified_by=designs)
    misfit = ms.residual_rms(state.evaluation.cost)
    success = final.converged
    if not final.converged:
        message = f"did not converge: {final.message}"
    else:
        message = final.message
        message += at_bound_clause(at_bound)
        if not_identified:
            message += f"; not identified (held at initial value): {', '.join(not_identified)}"
        poorly = [n for n in stats.names if not estimates[n].identified and n not in at_bound]
        if poorly:
            message += (
                f"; poorly determined (relative std > {options.identifiability_threshold:.0%}, "
                f"kept at their estimates): {', '.join(poorly)}"
            )
    values = {n: float(v) for n, v in zip(names, p, strict=True)}
    values.update({k: v for k, v in problem.initial.values.items() if k not in values})
    parameters = ParameterSet(
        variant=problem.initial.variant,
        values=values,
        title=f"{problem.initial.variant} fitted to {len(problem.experiments)} recording(s)",
        source="hframe-id fit (multiple shooting, Gauss-Newton)",
        references=list(problem.initial.references),
    )
    first = ms.first_window
    return FitResult(
        success=success,
        message=message,
        parameters=parameters,
        estimates=estimates,
        cost=float(state.evaluation.cost),
        iterations=int(sum(s.iterations for s in stages)),
        wall_time_s=time.perf_counter() - start,
        correlation=stats.correlation,
        free_names=stats.names,
        initial=problem.initial,
        options=options,
        stages=stages,
        statistics=stats,
        not_identified=not_identified,
        initial_states=state.nodes[first].copy(),
        experiment_names=tuple(e.name for e in problem.experiments),
        evaluations=gn.evaluations,
        problem=problem,
        equation_error=None if regression is None else regression[0],
        diagnostics=FitDiagnostics(
            channel_std=dict(zip(problem.output_names, problem.channel_std.tolist(), strict=True)),
            channel_rms=channel_rms(ms, state.evaluation),
            residual_rms_noise_std=misfit,
            at_default_box=tuple(at_box),
        ),
    )
