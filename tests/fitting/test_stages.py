"""The solver stages fits are made of (``fitting.stages``): the exact stage by the solver the
options name, continuity as a penalty, the state-estimation pre-pass and the equation-error
report. Exact data (``exact_shooting``) give the optimum the stages head for: theta = 0 on
the simulated trajectory."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hframe_id.errors import OptionError
from hframe_id.fitting import FitOptions, solvers
from hframe_id.fitting.link_options import SolverOptions
from hframe_id.fitting.solver import GaussNewton, SolverState
from hframe_id.fitting.stages import (
    equation_error_report,
    estimate_states,
    exact_stage,
    penalty_stage,
)
from hframe_id.fitting.strategy_settings import StrategySettings

#: The stages' default tuning, which these tests measure.
STRATEGY = StrategySettings()


def _merit(ms, nodes, theta, smoothing) -> float:
    """Cost plus the continuity defects as a penalty: 1/2 |r|^2 + w/2 |d|^2 (noise units)."""
    ev = ms.evaluate(nodes, theta, smoothing)
    return ev.cost + 0.5 * STRATEGY.penalty_weight * float(np.sum(ms.defects(ev, nodes) ** 2))


@pytest.fixture(scope="module")
def measured_start(exact_shooting):
    """The exact data's nodes from the measurements (positions measured, velocities from
    differences, unmeasured coordinates on the rigid motion) and the velocity estimate."""
    problem, ms, _ = exact_shooting
    return ms.initial_nodes(problem.p_initial)


def test_the_exact_stage_is_solved_by_the_solver_the_options_name(exact_shooting, monkeypatch):
    problem, ms, nodes = exact_shooting
    seen = []

    class Recorder:
        penalty_fallback = False
        description = "records its stage"

        def solve(self, stage):
            seen.append(stage)
            return "report"

    monkeypatch.setitem(solvers._REGISTERED, "recorder", Recorder())
    gn = GaussNewton(ms)
    state = SolverState(nodes.copy(), np.zeros(3), np.ones(3, dtype=bool))
    options = SolverOptions("recorder", max_iterations=5, step_tol=1e-6, defect_tol=1e-2)
    assert exact_stage(gn, state, "all windows", options, radius=0.25) == "report"
    (stage,) = seen
    assert stage.label == "all windows"
    assert stage.gauss_newton is gn and stage.state is state and stage.options is options
    assert stage.settings == {"radius": 0.25}


def test_an_exact_stage_by_a_solver_no_longer_registered_is_refused(exact_shooting, monkeypatch):
    """SolverOptions refuses an unknown name when made (test_options); a solver unregistered
    after its options were made is refused when the stage asks for it."""
    _, ms, nodes = exact_shooting
    state = SolverState(nodes.copy(), np.zeros(3), np.ones(3, dtype=bool))
    monkeypatch.setitem(solvers._REGISTERED, "newton-raphson", object())
    options = SolverOptions("newton-raphson", 5, 1e-6, 1e-2)
    monkeypatch.delitem(solvers._REGISTERED, "newton-raphson")
    with pytest.raises(OptionError, match="got 'newton-raphson'"):
        exact_stage(GaussNewton(ms), state, "all windows", options)


def test_the_penalty_stage_brings_a_poor_start_near_the_optimum(exact_shooting, measured_start):
    """From the measured nodes (velocities off by up to 0.3 m/s) and parameters 2 % off: the
    penalty stage lowers the merit and takes the parameters at least 20x closer to the
    optimum theta = 0 (it stops on a parameter step of ``intermediate_step_tol`` = 1e-4 or a
    relative gain of ``penalty_cost_rtol`` = 1e-3, so ~1e-3 of the 2e-2 may remain)."""
    problem, ms, _ = exact_shooting
    nodes, velocity = measured_start
    theta = np.array([0.02, -0.02, 0.02])
    state = SolverState(nodes.copy(), theta.copy(), np.ones(3, dtype=bool), velocity_hint=velocity)
    before = _merit(ms, nodes, theta, problem.smoothing)
    report = penalty_stage(GaussNewton(ms), state, problem.smoothing, FitOptions(), "all windows")
    assert report.name == "all windows, continuity as penalty"
    assert report.converged, report.message
    assert _merit(ms, state.nodes, state.theta, problem.smoothing) < before
    assert np.max(np.abs(state.theta)) <= np.max(np.abs(theta)) / 20


def test_state_estimation_moves_the_nodes_only(exact_shooting, measured_start):
    """At the true parameters, the pre-pass takes the measured nodes to the simulated
    trajectory, and its merit is the cost plus the penalised defects at the nodes it
    returns; the caller's arrays are left as they were."""
    problem, ms, true_nodes = exact_shooting
    nodes, velocity = measured_start
    given = nodes.copy()
    theta = np.zeros(3)
    stages = []
    estimated, merit = estimate_states(
        GaussNewton(ms), nodes, velocity, theta, np.ones(3, dtype=bool), stages, STRATEGY
    )
    assert np.array_equal(nodes, given) and np.array_equal(theta, np.zeros(3))
    assert [s.name for s in stages] == ["state estimation"]
    # The merit is recomputed here from its definition (rounding only: same evaluation).
    assert merit == pytest.approx(_merit(ms, estimated, theta, problem.smoothing), rel=1e-12)
    start_error = np.max(np.abs(nodes - true_nodes))
    # The start is off by up to 0.28 m/s (the velocities from differences); the pre-pass
    # stops on a node step below 1e-4 (``intermediate_step_tol``): a 100x reduction is far
    # inside what it reaches on exact data and far outside what a no-op gives.
    assert np.max(np.abs(estimated - true_nodes)) <= start_error / 100
    assert merit < 1e-4 * _merit(ms, nodes, theta, problem.smoothing)


def test_state_estimation_holds_the_parameters(exact_shooting, measured_start):
    """With the parameters 2 % off the pre-pass cannot reach zero merit: it fits the nodes
    to data of other parameters. Had it freed them, the merit would fall to that of the
    optimum theta = 0, which the test above bounds."""
    _, ms, _ = exact_shooting
    nodes, velocity = measured_start
    gn = GaussNewton(ms)
    _, held = estimate_states(
        gn, nodes, velocity, np.array([0.02, -0.02, 0.02]), np.ones(3, dtype=bool), [], STRATEGY
    )
    _, free = estimate_states(
        gn, nodes, velocity, np.zeros(3), np.ones(3, dtype=bool), [], STRATEGY
    )
    assert held > 100 * free


@pytest.mark.parametrize(
    ("used", "ending"), [(True, "used as the start"), (False, "worse than the given start")]
)
def test_the_equation_error_report_says_whether_its_estimate_was_kept(used, ending):
    report = equation_error_report(0.125, used)
    assert report.name == "equation error"
    assert report.message.startswith("regression on differentiated data: ")
    assert ending in report.message
    assert report.converged and report.iterations == 0 and report.wall_time_s == 0.125
    # No output-error evaluation was made: cost, defects and smoothing are not numbers.
    assert all(math.isnan(v) for v in (report.cost, report.max_defect, *report.smoothing))
