"""The output-error stages of a fit from one start (``fitting.output_error.solve``): the moving
windows, then every window; the pre-pass, the deferral to the noise rounds and the penalty
fallback. Exact data (``exact_shooting``) put the optimum at theta = 0; each solve starts
2 % off it from the nodes the measurements give (0.2-0.6 s a solve)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from hframe_id.fitting import FitOptions, output_error
from hframe_id.fitting.fit_run import FitRun
from hframe_id.fitting.solver import StageReport
from hframe_id.fitting.strategy_settings import StrategySettings

FREE = ("k_b", "M_cart", "b_bridge")
START = np.array([0.02, -0.02, 0.02])
#: Below the residual rms the moving windows end at on exact data (0.03-0.07 noise std: they
#: stop at the intermediate tolerances, steps of 1e-4), so that they count as a mismatch.
TINY_MISMATCH = StrategySettings(mismatch_rms=1e-3)


@pytest.fixture(scope="module")
def measured(exact_shooting):
    """The exact data's nodes from the measurements and the velocity estimate."""
    problem, ms, _ = exact_shooting
    return ms.initial_nodes(problem.p_initial)


@pytest.fixture()
def run(exact_shooting, measured):
    """``run(**options)``: a run on the exact data with k_b, M_cart, b_bridge free."""
    problem, ms, _ = exact_shooting
    nodes, velocity = measured

    def make(**options):
        options = FitOptions(free=FREE, **options).for_model("hframe-8")
        return FitRun(problem, options, ms, nodes, velocity, None, None, 0.0)

    return make


def _names(run):
    return [stage.name for stage in run.stages]


def test_the_moving_windows_then_every_window_reach_the_optimum(run):
    """The all-window stage stops on a parameter step below ``step_tol`` = 1e-6 at the
    optimum theta = 0; the evaluations of both stages are counted, and the caller's start
    is left as it was."""
    at = run()
    theta, active = START.copy(), np.ones(3, dtype=bool)
    state, gn = output_error.solve(at, theta, active)
    assert _names(at) == ["moving windows", "all windows"]
    assert at.stages[-1].converged, at.stages[-1].message
    assert np.max(np.abs(state.theta)) < 1e-6
    assert at.counter["evaluations"] > gn.evaluations > 0
    assert np.array_equal(theta, START) and active.all()


def test_without_the_first_stage_every_window_is_solved_from_the_start(run):
    at = run(first_stage=False)
    state, _ = output_error.solve(at, START, np.ones(3, dtype=bool))
    assert _names(at) == ["all windows"] and at.stages[-1].converged
    assert np.max(np.abs(state.theta)) < 1e-6


@pytest.mark.parametrize(
    ("noise", "defer", "deferred"),
    [
        ("auto", True, True),
        ("estimate", True, True),
        ("sensor", True, False),
        ("auto", False, False),
    ],
)
def test_moving_windows_far_above_the_noise_defer_the_all_window_stages(
    run, noise, defer, deferred
):
    """Only where asked (the first solve) and where the noise levels may be estimated: the
    stage then reports the moving windows' misfit, evaluated on every window, unconverged."""
    at = run(noise=noise, strategy=TINY_MISMATCH)
    state, _ = output_error.solve(at, START, np.ones(3, dtype=bool), defer_on_mismatch=defer)
    last = at.stages[-1]
    assert _names(at)[0] == "moving windows"
    if not deferred:
        assert _names(at)[1:] == ["all windows"] and last.converged
        return
    assert _names(at)[1:] == [output_error.DEFERRED_STAGE] and not last.converged
    assert last.message.startswith("residual rms ")
    assert "sensor std on the moving windows" in last.message
    assert state.evaluation.residual.shape[0] == at.ms.n_windows
    assert last.cost == state.evaluation.cost and np.isfinite(last.max_defect)
    # The moving windows moved the parameters: the rounds start from their end.
    assert 0 < np.max(np.abs(state.theta)) < np.max(np.abs(START)) / 10


@pytest.mark.parametrize("defer", [False, True])
def test_the_pre_pass_estimates_the_nodes_before_each_solve_but_not_before_a_deferral(run, defer):
    """The second estimate would follow the data discontinuously under mismatch."""
    at = run(strategy=TINY_MISMATCH)
    output_error.solve(at, START, np.ones(3, dtype=bool), prepass=True, defer_on_mismatch=defer)
    if defer:
        expected = ["state estimation", "moving windows", output_error.DEFERRED_STAGE]
    else:
        expected = ["state estimation", "moving windows", "state estimation", "all windows"]
    assert _names(at) == expected


@pytest.mark.parametrize("fallback", [True, False])
def test_a_failed_all_window_stage_falls_back_to_a_penalty_from_the_measured_nodes(
    run, monkeypatch, fallback
):
    """The exact stage (stood in for: it fails the first time) starts from the nodes the
    moving windows filled; if it fails, continuity as a penalty starts again from the
    measured nodes and the exact stage goes on from its end. A solver that globalises by
    itself (no ``penalty_fallback``) is not given a second try."""
    calls = []

    def stage(kind, name):
        def record(gn, state, *args, **kwargs):
            calls.append((kind, state, state.nodes.copy()))
            converged = kind == "penalty" or len(calls) > 1  # the first exact stage fails
            return StageReport(name, (0.0, 0.0), 1, converged, "stood in", 0.0, 0.0, 0.0)

        return record

    monkeypatch.setattr(output_error, "exact_stage", stage("exact", "all windows"))
    monkeypatch.setattr(output_error, "penalty_stage", stage("penalty", "penalty"))
    if not fallback:
        no_fallback = SimpleNamespace(penalty_fallback=False)
        monkeypatch.setattr(output_error, "solver_named", lambda name: no_fallback)
    at = run()
    output_error.solve(at, START, np.ones(3, dtype=bool))
    kinds = [kind for kind, _, _ in calls]
    assert not np.array_equal(calls[0][2], at.nodes)  # the moving windows' nodes
    if not fallback:
        assert kinds == ["exact"] and not at.stages[-1].converged
        return
    assert kinds == ["exact", "penalty", "exact"]
    assert _names(at) == ["moving windows", "all windows", "penalty", "all windows"]
    assert np.array_equal(calls[1][2], at.nodes) and calls[2][1] is calls[1][1]


@pytest.mark.parametrize("defer", [False, True])
def test_every_model_evaluation_is_counted(run, monkeypatch, defer):
    """The run's counter holds the evaluations of every iteration the stages built (the
    pre-pass's state estimates among them), plus the deferral's one evaluation."""
    built = []
    make_solver = FitRun.solver

    def recording(self, ms, freeze_sloppy=False):
        built.append(make_solver(self, ms, freeze_sloppy))
        return built[-1]

    monkeypatch.setattr(FitRun, "solver", recording)
    at = run(strategy=TINY_MISMATCH)
    output_error.solve(at, START, np.ones(3, dtype=bool), prepass=True, defer_on_mismatch=defer)
    assert sum(gn.evaluations > 0 for gn in built) >= 2  # a state estimate, the moving windows
    assert at.counter["evaluations"] == sum(gn.evaluations for gn in built) + int(defer)


@pytest.mark.parametrize(
    ("noise", "defer", "prepass", "gives_up"),
    [
        ("auto", True, False, True),  # its end only the noise rounds' start
        ("auto", False, False, False),  # a restart or a hold: judged by its converged end
        ("sensor", True, False, False),  # no rounds to hand over to
        ("auto", True, True, False),  # with a pre-pass only a converged stage defers
    ],
)
def test_the_fallback_gives_up_like_the_fast_path_only_where_the_rounds_take_over(
    run, monkeypatch, noise, defer, prepass, gives_up
):
    """The moving windows' fast path gives up on slow progress far from the noise level
    (``fast_path_patience``); its penalty fallback's exact stage does so too only where a
    result far above the sensors' noise is deferred to the noise rounds."""
    from hframe_id.fitting.solver import GaussNewton

    give_ups = []
    run_stage = GaussNewton.run

    def recording(self, state, stage, *args, give_up=None, **kwargs):
        if stage == "moving windows":
            give_ups.append(give_up)
            if len(give_ups) == 1:  # the fast path fails: the fallback runs
                return StageReport(stage, (0.0, 0.0), 1, False, "stood in", 0.0, 0.0, 0.0)
        return run_stage(self, state, stage, *args, give_up=give_up, **kwargs)

    monkeypatch.setattr(GaussNewton, "run", recording)
    at = run(noise=noise, strategy=TINY_MISMATCH)
    output_error.solve(at, START, np.ones(3, dtype=bool), prepass=prepass, defer_on_mismatch=defer)
    patience = StrategySettings().fast_path_patience
    assert give_ups == [patience, patience if gives_up else None]
