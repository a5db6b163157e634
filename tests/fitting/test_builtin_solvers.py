"""The built-in solvers of the all-window stage (``fitting.builtin_solvers``): each reaches the
known optimum of exact data from nearby, within the options' iterations, and says what it is.
Whole fits by every solver: integration/test_cross_method.py."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hframe_id.fitting import FitOptions, builtin_solvers
from hframe_id.fitting.builtin_solvers import GAUSS_NEWTON, IPOPT, SQPMETHOD
from hframe_id.fitting.nlp import NlpOutcome
from hframe_id.fitting.solver import GaussNewton, SolverState
from hframe_id.fitting.solvers import Stage, solver_named

#: A start 2 % off in each free log-parameter (k_b, M_cart, b_bridge): in the basin of the
#: exact data's optimum (from 5 %, -5 %, 10 % off, both solvers end in another local optimum
#: of the first windows' node states, at cost 229 where the optimum's is 0).
OFF = np.array([0.02, -0.02, 0.02])


def _stage(exact_shooting, theta, options=None, **settings) -> Stage:
    problem, ms, nodes = exact_shooting
    state = SolverState(nodes.copy(), theta.copy(), np.ones(len(problem.free), dtype=bool))
    options = options or FitOptions().solver_options
    return Stage("all windows", GaussNewton(ms), state, options, settings)


@pytest.mark.parametrize(
    "solver", [GAUSS_NEWTON, IPOPT, SQPMETHOD], ids=["gauss-newton", "ipopt", "sqpmethod"]
)
def test_each_solver_reaches_the_optimum_of_exact_data(exact_shooting, solver):
    """Exact data of Table 4.2: the optimum is theta = 0 with zero cost and defects.
    (``sqpmethod`` converges by its own tolerances here, or stops on its smallest search
    direction and is judged by the Gauss-Newton step from there, as the next test shows.)"""
    stage = _stage(exact_shooting, OFF, radius=0.5)
    report = solver.solve(stage)
    assert report.converged, report.message
    # Gauss-Newton stops on a parameter step <= step_tol = 1e-6, IPOPT and SQP at their
    # tolerance 1e-10; with zero residual at the optimum both converge quadratically, so the error
    # left after the last step is far below 1e-6.
    assert stage.state.theta == pytest.approx(0.0, abs=1e-6)
    # The cost is quadratic in that error: 1.0e4 at the start's 2 %, so an error of 1e-6
    # costs ~1e4 (1e-6 / 2e-2)^2 = 2.5e-5 (measured: 2.4e-5 for k_b alone, nodes held).
    assert report.cost <= 1e-4
    assert report.max_defect <= FitOptions().defect_tol
    assert report.cost == stage.state.evaluation.cost  # the report describes the end point


def test_the_gauss_newton_solver_stops_at_the_options_iterations(exact_shooting):
    options = replace(FitOptions().solver_options, max_iterations=1)
    report = GAUSS_NEWTON.solve(_stage(exact_shooting, OFF, options, radius=0.5))
    assert report.iterations == 1 and not report.converged
    assert "not converged in 1 iterations" in report.message


def test_the_gauss_newton_solver_converges_by_the_options_tolerances(exact_shooting):
    """With a step tolerance of 0.5 and a defect tolerance of 1e12 noise stds (none in
    effect; SolverOptions takes finite tolerances only), the first full step (2 % in each
    parameter, inside the radius 0.5) is already converged."""
    options = replace(FitOptions().solver_options, max_iterations=1, step_tol=0.5, defect_tol=1e12)
    report = GAUSS_NEWTON.solve(_stage(exact_shooting, OFF, options, radius=0.5))
    assert report.iterations == 1 and report.converged, report.message


def test_the_gauss_newton_solver_passes_its_stage_settings(exact_shooting):
    """A trust region of radius 1e-3 (on the step in the free log-parameters) cannot move the
    parameters by more than 1e-3 in one iteration, so one iteration from 2 % off ends at
    least 2e-2 - 1e-3 from the optimum (Euclidean norm)."""
    options = replace(FitOptions().solver_options, max_iterations=1)
    stage = _stage(exact_shooting, OFF, options, radius=1e-3, watchdog=False)
    GAUSS_NEWTON.solve(stage)
    assert np.linalg.norm(stage.state.theta - OFF) <= 1e-3 * (1 + 1e-9)


def test_an_nlp_solver_hands_its_settings_over_and_leaves_its_end_in_the_state(
    exact_shooting, monkeypatch
):
    """``NlpSolver.solve`` with a stand-in for ``solve_nlp`` (SQP itself takes ~10 s here):
    the solver's name and the options' iterations reach the NLP, its end point the state, and
    the report says the NLP did not converge when it says so."""
    problem, _, nodes = exact_shooting
    calls = []

    def fake_solve_nlp(ms, start_nodes, theta, active, smoothing, settings):
        calls.append(settings)
        return NlpOutcome(
            nodes=nodes,
            theta=np.zeros_like(theta),
            converged=False,
            message="Search Direction Too Small",
            iterations=7,
            cost=np.nan,  # the report evaluates the end point itself
            max_defect=np.nan,
            wall_time_s=0.0,
            substeps=(0, 0),
            build_time_s=0.0,
        )

    monkeypatch.setattr(builtin_solvers, "solve_nlp", fake_solve_nlp)
    options = replace(FitOptions().solver_options, max_iterations=42)
    stage = _stage(exact_shooting, OFF, options)
    report = SQPMETHOD.solve(stage)
    (settings,) = calls
    assert (settings.solver, settings.max_iter) == ("sqpmethod", 42)
    assert np.array_equal(stage.state.theta, np.zeros(len(problem.free)))
    assert report.name == "all windows (SQP)" and report.iterations == 7
    assert not report.converged and report.message == "Search Direction Too Small"
    assert report.cost == pytest.approx(0.0, abs=1e-12)  # the end point is the exact optimum


@pytest.mark.parametrize(
    ("name", "penalty_fallback", "description"),
    [
        ("gauss-newton", True, "Gauss-Newton on the lifted problem (CasADi)"),
        ("ipopt", False, "IPOPT (CasADi nlpsol, Gauss-Newton Hessian)"),
        ("sqpmethod", False, "SQP (CasADi nlpsol, Gauss-Newton Hessian)"),
    ],
)
def test_each_built_in_name_gives_its_solver_and_says_how_it_globalises(
    name, penalty_fallback, description
):
    """Only the local Gauss-Newton iteration needs the penalty fallback from a poor start;
    the description is what the parameter file's provenance states."""
    solver = solver_named(name)
    assert solver.penalty_fallback is penalty_fallback
    assert solver.description == description


@pytest.mark.parametrize(("end", "converged"), [(OFF, False), (np.zeros(3), True)])
def test_sqps_small_step_stop_is_judged_by_the_gauss_newton_step_from_its_end(
    exact_shooting, monkeypatch, end, converged
):
    """``sqpmethod`` also stops on a small search direction where its QP failed (no step):
    that is converged only where the Gauss-Newton step from the end point is within
    ``step_tol`` (at the optimum, theta = 0), not 2 % away from it."""
    problem, _, nodes = exact_shooting

    def fake_solve_nlp(ms, start_nodes, theta, active, smoothing, settings):
        return NlpOutcome(
            nodes,
            end.copy(),
            False,
            "Search Direction Becomes Too Small",
            3,
            np.nan,
            np.nan,
            0.0,
            4,
            0.0,
            small_step=True,
        )

    monkeypatch.setattr(builtin_solvers, "solve_nlp", fake_solve_nlp)
    report = SQPMETHOD.solve(_stage(exact_shooting, OFF))
    assert report.converged is converged
    assert "the Gauss-Newton step from there" in report.message
    assert ("<= 1e-06" in report.message) is converged
