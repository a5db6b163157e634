"""Restarts along the springs at an unmeasured coordinate (``fitting.unmeasured``): the
search over moves, with the solves replaced by a stand-in whose cost is known."""

import math
from types import SimpleNamespace

import numpy as np

from hframe_id.fitting import FitOptions, unmeasured
from hframe_id.fitting.fit_run import Fitted
from hframe_id.fitting.solver import SolverState, StageReport


def _report(name="solve", cost=0.0):
    return StageReport(name, (0.0, 0.0), 1, True, "converged", cost, 0.0, 0.0)


def test_a_move_is_not_solved_twice_from_the_same_best(monkeypatch):
    """Two springs, four moves each: the first move improves (the search goes on from
    there), none after it does. Each (move, point moved from) is solved once: 8 moves from
    the start's best, then only the move that had been tried before the improvement, again
    from the new best: 9 solves, where repeating every move of the second pass took 16."""
    solved = []

    def solve(trial, theta, active, prepass):
        solved.append(np.round(theta, 12).tobytes())
        cost = 10.0 if len(solved) == 1 else 100.0  # only the first move improves
        trial.stages.append(_report(cost=cost))
        return SolverState(None, theta, active, SimpleNamespace(cost=cost)), "solver"

    monkeypatch.setattr(unmeasured, "solve", solve)
    monkeypatch.setattr(unmeasured, "springs_at_unmeasured_coordinates", lambda problem, ms: [0, 1])
    problem = SimpleNamespace(
        free_names=("k2", "k3"), theta_lower=np.full(2, -9.0), theta_upper=np.full(2, 9.0)
    )
    run = SimpleNamespace(
        problem=problem,
        options=FitOptions(),  # the default restarts: x/÷1.18 and 1.4, at most 16
        ms=SimpleNamespace(residual_rms=lambda cost: 1.0),  # at the noise level
        stages=[_report(cost=50.0)],
        trial=lambda label: SimpleNamespace(stages=[]),
        statistics=lambda gn, state: "statistics",
    )
    start = SolverState(None, np.zeros(2), np.ones(2, bool), SimpleNamespace(cost=50.0))
    fitted = unmeasured.restarts_along_unmeasured_springs(run, Fitted(start, "solver", None))
    assert len(solved) == len(set(solved)) == 9
    assert fitted.state.evaluation.cost == 10.0
    assert "9 restarts" in run.stages[-1].message


def test_a_move_the_box_stops_is_solved_once_and_none_at_the_bound(monkeypatch):
    """k2 on its lower bound, k3 0.1 below its upper one (log): k2's two lowering moves leave
    it on the bound (no restart), k3's raising moves x1.18 (0.166) and x1.4 (0.336) both stop
    at the bound (one restart). Nothing improves: 2 + 1 + 2 = 5 solves, where solving each
    factor took 8 (three of them from the start's own point or twice from one)."""
    solved = []

    def solve(trial, theta, active, prepass):
        solved.append(theta.copy())
        trial.stages.append(_report(cost=100.0))
        return SolverState(None, theta, active, SimpleNamespace(cost=100.0)), "solver"

    monkeypatch.setattr(unmeasured, "solve", solve)
    monkeypatch.setattr(unmeasured, "springs_at_unmeasured_coordinates", lambda problem, ms: [0, 1])
    problem = SimpleNamespace(
        free_names=("k2", "k3"), theta_lower=np.array([0.0, -9.0]), theta_upper=np.array([9, 0.1])
    )
    labels = []
    run = SimpleNamespace(
        problem=problem,
        options=FitOptions(),
        ms=SimpleNamespace(residual_rms=lambda cost: 1.0),
        stages=[_report(cost=50.0)],
        trial=lambda label: labels.append(label) or SimpleNamespace(stages=[]),
        statistics=lambda gn, state: "statistics",
    )
    start = SolverState(None, np.zeros(2), np.ones(2, bool), SimpleNamespace(cost=50.0))
    unmeasured.restarts_along_unmeasured_springs(run, Fitted(start, "solver", None))
    moves = sorted((int(np.flatnonzero(t)[0]), round(float(t[t != 0][0]), 12)) for t in solved)
    k2_up = [(0, round(math.log(f), 12)) for f in (1.18, 1.4)]
    k3_down = [(1, round(-math.log(f), 12)) for f in (1.18, 1.4)]
    assert moves == sorted([*k2_up, (1, 0.1), *k3_down])
    assert "k3 x1.11" in labels[2]  # the move as the bound left it: e^0.1
