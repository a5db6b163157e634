"""The solver stages the fits are made of: exact continuity over every window (by the
solver the options name), continuity as a penalty, and the state-estimation pre-pass."""

from __future__ import annotations

import math

import numpy as np

from hframe_id.fitting.link_options import SolverOptions
from hframe_id.fitting.options import FitOptions
from hframe_id.fitting.solver import GaussNewton, SolverState, StageReport
from hframe_id.fitting.solvers import Stage, solver_named
from hframe_id.fitting.strategy_settings import StrategySettings


def exact_stage(
    gn: GaussNewton, state: SolverState, label: str, options: SolverOptions, **settings
) -> StageReport:
    """Every window with exact continuity, to the ``options``' tolerances, by the solver they
    name (``fitting.solvers``), from ``state``, which it updates; ``settings`` are the
    Gauss-Newton solver's own (``GaussNewton.run``)."""
    solver = solver_named(options.solver)
    return solver.solve(Stage(label, gn, state, options, settings))


def penalty_stage(
    gn: GaussNewton,
    state: SolverState,
    smoothing: tuple[float, float],
    options: FitOptions,
    windows: str,
) -> StageReport:
    """Continuity as a penalty (``StrategySettings.penalty_weight``): a monotone
    trust-region method that brings far-off nodes into the basin of the exact condensed
    iteration, stopping once an iteration gains under ``penalty_cost_rtol``."""
    strategy = options.strategy
    return gn.run(
        state,
        f"{windows}, continuity as penalty",
        smoothing,
        options.max_iterations,
        strategy.intermediate_step_tol,
        math.inf,
        cost_rtol=strategy.penalty_cost_rtol,
        radius=1.0,
        penalty=strategy.penalty_weight,
    )


def estimate_states(
    gn: GaussNewton, nodes, velocity, theta, active, stages, strategy: StrategySettings
):
    """State-estimation pre-pass: the node states of ``gn``'s transcription with the
    parameters held at ``theta``, within ``strategy``'s pre-pass settings; the stage's
    report is appended to ``stages``. Returns (nodes, merit): the merit with continuity as
    the penalty [chi^2 / 2].

    The nodes from the data put unmeasured coordinates (and lasers out of range) on the
    rigid motion (belts unstretched); the continuity defects that leaves make the first
    Gauss-Newton steps in the parameters large (0.3-0.4 in log p even at the truth). Here
    continuity is a penalty and only the nodes move; the parameters are released after.
    """
    ms = gn.ms
    state = SolverState(nodes.copy(), theta.copy(), np.zeros_like(active), velocity_hint=velocity)
    stages.append(
        gn.run(
            state,
            "state estimation",
            ms.problem.smoothing,
            strategy.prepass_iterations,
            strategy.intermediate_step_tol,
            strategy.intermediate_defect_tol,
            cost_rtol=strategy.prepass_cost_rtol,
            radius=1.0,
            penalty=strategy.penalty_weight,
        )
    )
    ev = state.evaluation
    merit = ev.cost + 0.5 * strategy.penalty_weight * float(
        np.sum(ms.defects(ev, state.nodes) ** 2)
    )
    return state.nodes, merit


def equation_error_report(seconds: float, used: bool) -> StageReport:
    """The report of the equation-error stage: ``seconds`` [s] and whether its estimate was
    kept as the start."""
    return StageReport(
        name="equation error",
        smoothing=(math.nan, math.nan),
        iterations=0,
        converged=True,
        message="regression on differentiated data: "
        + ("used as the start" if used else "worse than the given start, not used"),
        cost=math.nan,
        max_defect=math.nan,
        wall_time_s=seconds,
    )
