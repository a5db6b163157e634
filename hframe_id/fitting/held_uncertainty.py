"""The intervals of a fit widened by the uncertainty of the parameters it held."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from hframe_id.fitting.consider import Consider, consider_covariance
from hframe_id.fitting.estimates import ended_at_bound
from hframe_id.fitting.link_options import HELD_PRIOR_RELATIVE_STD
from hframe_id.fitting.problem import build_problem, consider_priors
from hframe_id.fitting.result import spread
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.fitting.solver import GaussNewton


def include_held_uncertainty(problem, recordings, state, result):
    """``result`` with the free parameters' intervals widened by the consider covariance of
    the held ones (``FitOptions.consider``), and a record of what the intervals assume.
    Refits and linearisations use the options ``result`` was fitted with."""
    options = result.options
    names = problem.model.parameter_names
    prior = consider_priors(problem.model, options.consider)
    if options.consider is None:
        prior.update({n: HELD_PRIOR_RELATIVE_STD for n in result.not_identified})
    p = problem.parameters(state.theta)
    held = [n for n in names if n in prior and n not in result.free_names and p[names.index(n)]]
    held_relative_std = {n: prior[n] for n in held}
    if not held or not result.free_names:
        return result.with_diagnostics(consider=Consider(held_relative_std))
    failed: list[str] = []
    if options.consider_method == "refit":
        variances, failed = _refit_consider_variances(
            problem, options, recordings, state, held, prior
        )
        variances = {n: variances[problem.free_names.index(n)] for n in result.free_names}
    else:
        variances = _linear_consider_variances(problem, recordings, state, result, held, prior)
    z = result.statistics.z_value(options.confidence)
    extra = {}
    estimates = dict(result.estimates)
    for name in result.free_names:
        est = result.estimates[name]
        f = problem.free_names.index(name)
        signed, scale = problem.linear[f], problem.linear_scale[f]
        variance = max(float(variances[name]), 0.0)
        theta_std = est.std_error / scale if signed else est.relative_std
        std, rel, ci95 = spread(est.estimate, math.sqrt(theta_std**2 + variance), signed, scale, z)
        if est.at_bound:
            ci95 = ended_at_bound(problem, state, f, ci95)
        extra[name] = math.sqrt(variance)
        estimates[name] = replace(est, relative_std=rel, std_error=std, ci95=ci95)
    consider = Consider(held_relative_std, options.consider_method, extra, tuple(failed))
    return replace(result, estimates=estimates).with_diagnostics(consider=consider)


def _linear_consider_variances(problem, recordings, state, result, held, prior) -> dict:
    """Per free parameter (name), the variance (in its theta units) the held parameters' priors add,
    linearised at the optimum: diag S P S^T (``consider.consider_covariance``)."""
    widened = build_problem(
        recordings,
        problem.parameter_set(state.theta),
        replace(result.options, free=result.free_names + tuple(held), fix=(), bounds={}),
    )
    ms = MultipleShooting(widened, transcription=result.options.transcription_options).uniform()
    theta = np.zeros(len(widened.free))
    ev = ms.evaluate(state.nodes, theta, widened.smoothing)
    jac, _, _ = GaussNewton(ms).condensed_jacobian(ev, state.nodes, np.ones(theta.size, bool))
    n_estimated = ms.n_nuisance + len(result.free_names)
    added = consider_covariance(
        jac[:, :n_estimated], jac[:, n_estimated:], np.array([prior[n] for n in held])
    )
    offset = n_estimated - len(result.free_names)
    return {name: added[offset + k, offset + k] for k, name in enumerate(result.free_names)}


def _refit_consider_variances(
    problem, options, recordings, state, held, prior
) -> tuple[np.ndarray, list[str]]:
    """Per free parameter (``problem.free`` order), the variance (in its theta units) the held
    parameters' priors add, from refits: the whole fit (``options``, quiet and without
    consider priors) repeated from its start with each held value at exp(+/-sigma) times
    itself, and half the difference of the two estimates taken as that prior's one-sigma
    effect. A held idler 15 % off moved the one-axis fit's B_1 by +52 %
    where the tangent at the optimum predicts 5 %, and warm-started refits (which stay in the
    optimum's basin) covered no better than the tangent (docs/fitting.md). Also returns the
    refits that did not converge ("name xfactor: message"); their ends count all the same,
    stated in the held statement.
    """
    from hframe_id.fitting.fit import fit_recordings  # the whole fit, which imports this module

    names = problem.model.parameter_names
    p = problem.parameters(state.theta)
    quiet = replace(options, consider={}, verbose=0, progress=None)
    variances = np.zeros(len(problem.free))
    failed = []
    for name in held:
        ends = []
        for sign in (1.0, -1.0):
            factor = math.exp(sign * prior[name])
            value = float(p[names.index(name)]) * factor
            refit = fit_recordings(
                recordings, problem.initial.replace_values(**{name: value}), quiet
            )
            if not refit.success:
                failed.append(f"{name} x{factor:.3g}: {refit.message}")
            ends.append(problem.theta_of(refit.parameters))
        variances += ((ends[0] - ends[1]) / 2.0) ** 2
    return variances, failed
