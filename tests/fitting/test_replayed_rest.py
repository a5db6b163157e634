"""The fit's last solve from the replay's rest state (``fitting.replayed_rest``), on stand-ins:
when it is needed, where it starts, and what becomes of one that stops unconverged (kept if
it replays better than the stages' end, else rejected). Whole fits through it:
integration/test_replayed_rest_fits.py."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from hframe_id.fitting import FitOptions, replayed_rest
from hframe_id.fitting.fit_run import FitRun, Fitted
from hframe_id.fitting.link_options import ProblemOptions
from hframe_id.fitting.solver import SolverState, StageReport

STAGE = replayed_rest.STAGE
#: The evaluations at the stages' end and at the last solve's (chi^2 / 2).
EV_BEST = SimpleNamespace(cost=4.0)
EV_END = SimpleNamespace(cost=3.0)


@pytest.mark.parametrize(
    ("rest_start", "continuity", "at_rest", "replays"),
    [
        ("rigid", "exact", (False, True), True),
        ("rigid", "exact", (False, False), False),  # no record at rest
        ("replay", "exact", (True,), False),  # the stages started from the replay's state
        ("rigid", "none", (True,), False),  # equation error: no trajectory from rest
    ],
)
def test_the_last_solve_is_for_an_output_error_fit_that_estimated_a_rest_position(
    rest_start, continuity, at_rest, replays
):
    options = FitOptions(rest_start=rest_start, continuity=continuity)
    experiments = [SimpleNamespace(at_rest=a) for a in at_rest]
    run = SimpleNamespace(options=options, problem=SimpleNamespace(experiments=experiments))
    assert replayed_rest.replays_rest(run) is replays


def test_the_replay_is_judged_at_the_fits_weights_and_latencies(monkeypatch):
    seen = []

    def criterion(params, recordings, std, latency):
        seen.append((params, recordings, std, latency))
        return 12.5

    monkeypatch.setattr(replayed_rest, "simulation_criterion", criterion)
    problem = SimpleNamespace(
        output_names=("phi1", "x"),
        # the fit's, e.g. noise levels estimated per recording
        recording_std=np.array([[2e-5, 1e-5], [3e-5, 4e-5]]),
        problem_options=ProblemOptions(latency_samples={"x": 2}),
        parameter_set=lambda theta: f"parameters at {theta.tolist()}",
    )
    judge = replayed_rest._replay_criterion(problem, ["first", "second"])
    assert judge(np.array([0.5])) == 12.5
    levels = [{"phi1": 2e-5, "x": 1e-5}, {"phi1": 3e-5, "x": 4e-5}]
    assert seen == [("parameters at [0.5]", ["first", "second"], levels, {"x": 2})]


class _Shooting:
    """A stand-in for the replay's transcription: two records whose first windows are 0
    (at rest) and 3 (in motion), its fresh nodes all 9, its defects up to 2 noise std."""

    made: list[_Shooting] = []
    first_window = np.array([0, 3])

    def __init__(self, problem, transcription):
        self.transcription = transcription
        _Shooting.made.append(self)

    def initial_nodes(self, p):
        return np.full((6, 2), 9.0), None

    def defects(self, evaluation, nodes):
        return np.array([0.5, -2.0])


@pytest.fixture()
def last_solve(monkeypatch):
    """``last_solve(converged, judged)``: (run, best, returned run, returned end, the start of
    the solve) of ``solve_from_replayed_rest`` with the solve stood in for (it ends at theta
    [0.1, 0.1], cost 3, ``converged``) and the replays judged by ``judged(theta)``."""
    _Shooting.made.clear()
    monkeypatch.setattr(replayed_rest, "MultipleShooting", _Shooting)
    monkeypatch.setattr(FitRun, "statistics", lambda run, gn, state: ("statistics of", gn))

    def make(converged, judged=None):
        starts = []

        def warm_solve(run, start, label, estimated=False, sensor_std=None):
            starts.append(start)
            run.stages.append(
                StageReport(label, (0.0, 0.0), 150, converged, "150 iterations", 3.0, 0.0, 0.0)
            )
            end = SolverState(start.nodes, np.array([0.1, 0.1]), start.active, EV_END)
            return end, "last solver"

        monkeypatch.setattr(replayed_rest, "warm_solve", warm_solve)
        monkeypatch.setattr(replayed_rest, "_replay_criterion", lambda problem, recs: judged)
        experiments = [SimpleNamespace(at_rest=True), SimpleNamespace(at_rest=False)]
        problem = SimpleNamespace(experiments=experiments, parameters=lambda theta: theta)
        ms = SimpleNamespace(defects=lambda evaluation, nodes: np.array([0.25]))
        options = FitOptions().for_model("hframe-8")
        stages = [StageReport("all windows", (0.0, 0.0), 5, True, "converged", 4.0, 0.0, 0.0)]
        run = FitRun(problem, options, ms, None, None, None, None, 0.0, stages)
        nodes = np.arange(12.0).reshape(6, 2)
        state = SolverState(nodes, np.array([0.2, 0.3]), np.ones(2, dtype=bool), EV_BEST)
        best = Fitted(state, "stages' solver", "stages' statistics", {"d": (2.0, 1.0, 0.9)})
        ended_run, ended = replayed_rest.solve_from_replayed_rest(run, best, ["recording"])
        return run, best, ended_run, ended, starts[0]

    return make


def test_a_converged_last_solve_starts_the_records_at_rest_from_the_replays_state(last_solve):
    """The first node of the record at rest is the replay's; every other node and the
    parameters are the stages' end (warm); the run goes on with the replay's rest state."""
    run, best, ended_run, ended, start = last_solve(converged=True)
    (ms,) = _Shooting.made
    assert ms.transcription.rest_start == "replay" and ended_run.options.rest_start == "replay"
    assert ended_run.ms is ms and ended_run.counter is run.counter
    expected = best.state.nodes.copy()
    expected[0] = 9.0
    assert np.array_equal(start.nodes, expected)
    assert np.array_equal(best.state.nodes, np.arange(12.0).reshape(6, 2))  # left as it was
    assert np.array_equal(start.theta, best.state.theta) and start.theta is not best.state.theta
    assert [s.name for s in ended_run.stages] == ["all windows", STAGE]
    assert ended.solver == "last solver" and ended.statistics == ("statistics of", "last solver")
    assert ended.held == best.held and ended.state.theta.tolist() == [0.1, 0.1]


def test_an_unconverged_last_solve_that_replays_better_is_kept_saying_so(last_solve):
    """Judged by theta[0]: the last solve's end (0.1) replays better than the stages' (0.2)."""
    run, best, ended_run, ended, _ = last_solve(converged=False, judged=lambda t: float(t[0]))
    verdict = ended_run.stages[-1]
    names = [s.name for s in ended_run.stages]
    assert names == ["all windows", STAGE, f"{STAGE}: kept unconverged"]
    assert verdict.converged and verdict.iterations == 0
    # The kept end's cost, and its largest defect on the replay's transcription.
    assert (verdict.cost, verdict.max_defect) == (3.0, 2.0)
    assert "stopped unconverged (150 iterations)" in verdict.message
    assert "(chi^2 / 2 0.1 against 0.2)" in verdict.message
    assert ended_run.options.rest_start == "replay" and ended.state.theta.tolist() == [0.1, 0.1]


@pytest.mark.parametrize("judged", [lambda t: 1.0, lambda t: -float(t[0])], ids=["same", "worse"])
def test_an_unconverged_last_solve_that_replays_no_better_is_rejected(last_solve, judged):
    """The fit keeps the stages' end, as it was, and says why."""
    run, best, ended_run, ended, _ = last_solve(converged=False, judged=judged)
    assert ended_run is run and ended is best
    verdict = run.stages[-1]
    assert verdict.name == f"{STAGE}: rejected" and verdict.converged
    # The stages' end's cost, and its largest defect on the stages' transcription.
    assert (verdict.cost, verdict.max_defect) == (4.0, 0.25)
    assert verdict.message.endswith("the fit keeps the belt-free positions it estimated")
    assert "did not converge (150 iterations)" in verdict.message
