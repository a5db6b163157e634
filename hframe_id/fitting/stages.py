"""The solver stages the fits are made of: exact continuity over every window (by the
solver the options name), continuity as a penalty, and the state-estimation pre-pass."""

from __future__ import annotations

import math

import numpy as np

from hframe_id.fitting.options import FitOptions, SolverOptions
from hframe_id.fitting.solver import GaussNewton, SolverState, StageReport
from hframe_id.fitting.solvers import Stage, solver_named

#: Fallback stage on the moving windows when exact continuity from the equation-error start
#: fails: continuity as a penalty (defects in noise units, this weight), a monotone
#: trust-region method that stops once an iteration gains less than ``PENALTY_COST_RTOL``;
#: it takes a poor start into the basin of the exact (condensed) Gauss-Newton iteration.
PENALTY_WEIGHT = 1.0


PENALTY_COST_RTOL = 1e-3


#: Tolerances of the intermediate stages (the last stage uses the options' step_tol):
#: they only need to bring the iterate into the next stage's basin.
INTERMEDIATE_STEP_TOL = 1e-4


INTERMEDIATE_DEFECT_TOL = 1.0


#: Iterations of the state-estimation pre-pass (nodes only, parameters held), and the
#: relative decrease of its merit per iteration below which it stops earlier.
PREPASS_ITERATIONS = 30


PREPASS_COST_RTOL = 1e-4


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
    """Continuity as a penalty (see PENALTY_WEIGHT): brings far-off nodes into the basin of
    the exact condensed iteration, stopping once an iteration gains under PENALTY_COST_RTOL."""
    return gn.run(
        state,
        f"{windows}, continuity as penalty",
        smoothing,
        options.max_iterations,
        INTERMEDIATE_STEP_TOL,
        math.inf,
        cost_rtol=PENALTY_COST_RTOL,
        radius=1.0,
        penalty=PENALTY_WEIGHT,
    )


def estimate_states(gn: GaussNewton, nodes, velocity, theta, active, stages):
    """State-estimation pre-pass: the node states of ``gn``'s transcription with the
    parameters held at ``theta``; the stage's report is appended to ``stages``.

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
            PREPASS_ITERATIONS,
            INTERMEDIATE_STEP_TOL,
            INTERMEDIATE_DEFECT_TOL,
            cost_rtol=PREPASS_COST_RTOL,
            radius=1.0,
            penalty=PENALTY_WEIGHT,
        )
    )
    ev = state.evaluation
    merit = ev.cost + 0.5 * PENALTY_WEIGHT * float(np.sum(ms.defects(ev, state.nodes) ** 2))
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
