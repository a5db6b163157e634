"""Holding the free parameters the data do not identify, and solving again without them.

After the output-error stages, a free parameter whose relative standard error exceeds
``FitOptions.identifiability_threshold`` is held at its initial value (the worst first,
with every one the data plainly do not determine) and the rest solved again, until every
parameter left is identified; ``design_advice`` names the experiments that would identify
each held one.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hframe_id.fitting.fit_run import FitRun, Fitted
from hframe_id.fitting.solver import GaussNewton, SolverState


def hold_unidentified(
    run: FitRun,
    fitted: Fitted,
    resolve: Callable[[np.ndarray, np.ndarray], tuple[SolverState, GaussNewton]],
) -> Fitted:
    """``fitted`` with the free parameters whose relative standard error exceeds the
    identifiability threshold held at their initial value, the worst first, each time
    solved again by ``resolve(theta, active) -> (state, solver)`` (log-parameters, which
    are free), until every parameter left is identified. Parameters whose error is above
    ``StrategySettings.hopeless_std`` are held with the worst; an unconverged fit above
    ``hold_misfit`` noise std holds nothing."""
    problem, strategy = run.problem, run.options.strategy
    state, gn, stats = fitted.state, fitted.solver, fitted.statistics
    held = dict(fitted.held)
    for _ in range(len(problem.free)):
        # Also when the stage did not converge, if the fit is at the noise level: a sloppy
        # direction (a parameter the data hardly determine) is the usual reason, and holding
        # it lets the rest converge. Far from a fit, error estimates mean nothing: fail.
        misfit = run.ms.residual_rms(state.evaluation.cost)
        if not run.stages[-1].converged and misfit > strategy.hold_misfit:
            break
        active_idx = np.flatnonzero(state.active)
        # A parameter with a prior (``FitProblem.prior_weight``) is never held: the prior
        # determines what the data do not.
        judged = np.where(problem.prior_weight[active_idx] > 0, 0.0, stats.relative_std)
        worst = int(np.argmax(judged))
        if judged[worst] <= run.options.identifiability_threshold:
            break
        # The worst first (fixing one of a collinear pair can identify the other), together
        # with every parameter the data plainly do not determine (relative std > 100 %).
        hold = {worst} | set(np.flatnonzero(judged > strategy.hopeless_std).tolist())
        if len(hold) == len(active_idx):
            # Nothing would be left to fit: the parameters stay free at their fitted values
            # and the report's statistics say how poorly the data determine them.
            break
        active = state.active.copy()
        theta = state.theta.copy()
        for k in sorted(hold):
            index = int(active_idx[k])
            held[problem.free_names[index]] = (
                float(stats.relative_std[k]),
                float(stats.relative_std_gn[k]),
                float(stats.collinearity[k]),
            )
            active[index] = False
            theta[index] = 0.0
        state, gn = resolve(theta, active)
        stats = run.statistics(gn, state)
    return Fitted(state, gn, stats, held)
