"""What the stages of one fit share (``fitting.fit_run``): the iteration each stage builds, the
statistics at a stage's end, a trial's own stage list beside the shared count of model
evaluations, and the result of the run's end. Exact data (``exact_shooting``) put the
optimum at theta = 0 on the simulated trajectory."""

from __future__ import annotations

import numpy as np
import pytest

from hframe_id.fitting import FitOptions
from hframe_id.fitting.fit_run import FitRun, Fitted
from hframe_id.fitting.options import FitProgress
from hframe_id.fitting.solver import SolverState, StageReport

FREE = ("k_b", "M_cart", "b_bridge")


def _report(name="all windows", iterations=3, cost=0.0):
    return StageReport(name, (1e-3, 1e-2), iterations, True, "converged", cost, 0.0, 0.0)


def _line(stage="all windows"):
    return FitProgress(stage=stage, iteration=1, cost=2.0, step=0.1, defect=0.0)


def test_a_trial_has_its_own_stages_and_counts_its_evaluations_with_the_run():
    run = FitRun(None, FitOptions(), None, None, None, None, None, 0.0, [_report()])
    run.add_evaluations(4)
    trial = run.trial("restart 1")
    assert trial.stages == []
    trial.stages.append(_report("restart"))
    trial.add_evaluations(5)
    assert [s.name for s in run.stages] == ["all windows"]
    assert run.counter == {"evaluations": 9} and trial.counter is run.counter


def test_a_trials_iterations_report_under_its_label(shooting_setup):
    """The solver a trial builds reports to the run's sink, each line's stage prefixed."""
    _, ms, _, _ = shooting_setup
    lines = []
    run = FitRun(None, FitOptions(), ms, None, None, None, lines.append, 0.0)
    run.trial("restart 1").solver(ms).progress(_line())
    run.solver(ms).progress(_line("moving windows"))
    assert [line.stage for line in lines] == ["restart 1: all windows", "moving windows"]
    assert FitRun(None, FitOptions(), ms, None, None, None, None, 0.0).trial("x").progress is None


@pytest.mark.parametrize("method", ["robust", "gauss-newton"])
def test_the_statistics_are_of_the_active_parameters_by_the_options_method(shooting_setup, method):
    """k_r held (inactive): the statistics name the other free parameters, in order, with the
    method ``FitOptions.uncertainty`` names; the Gauss-Newton method's stds are the textbook
    ones exactly, the robust ones differ (noisy data: the sandwich is not J^T J)."""
    problem, ms, nodes, _ = shooting_setup
    theta = np.zeros(len(problem.free_names))
    active = np.array([name != "k_r" for name in problem.free_names])
    state = SolverState(nodes, theta, active, ms.evaluate(nodes, theta, problem.smoothing))
    run = FitRun(problem, FitOptions(uncertainty=method), ms, None, None, None, None, 0.0)
    stats = run.statistics(run.solver(ms), state)
    assert stats.names == tuple(n for n in problem.free_names if n != "k_r")
    assert stats.method == method and stats.relative_std.shape == (len(stats.names),)
    same = np.array_equal(stats.relative_std, stats.relative_std_gn)
    assert same is (method == "gauss-newton")


def test_the_result_is_the_runs_stages_at_the_fitted_end(exact_shooting):
    """At the exact data's optimum: the start's values, cost 0 up to rounding (1e-12 chi^2 / 2
    of residuals that are the transcription's own simulation), the stages and iterations
    of the run (not of a trial), the equation-error estimate it was given."""
    problem, ms, nodes = exact_shooting
    theta = np.zeros(len(FREE))
    state = SolverState(nodes, theta, np.ones(len(FREE), dtype=bool))
    state.evaluation = ms.evaluate(nodes, theta, problem.smoothing)
    regression = (np.full(len(FREE), 0.01), 0.2)
    options = FitOptions(free=FREE)
    run = FitRun(problem, options, ms, None, None, regression, None, 0.0, [_report()])
    run.trial("restart").stages.append(_report("restart", iterations=50))
    gn = run.solver(ms)
    result = run.result(Fitted(state, gn, run.statistics(gn, state)))
    assert result.success and result.stages == run.stages and result.iterations == 3
    assert result.free_names == FREE and result.cost < 1e-12
    for name in FREE:
        assert result.estimates[name].estimate == pytest.approx(
            problem.initial.values[name], rel=1e-12
        )
    assert np.array_equal(result.equation_error, regression[0])
    assert result.not_identified == ()
