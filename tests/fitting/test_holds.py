"""Holding the free parameters the data do not identify (``fitting.holds``): which are held,
in what order, and what is solved again, on statistics given by hand for free parameters
a, b, c (the solves again replaced by a stand-in that records what it was asked)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from hframe_id.fitting import FitOptions, holds
from hframe_id.fitting.fit_run import FitRun, Fitted


def _hold(
    monkeypatch, rounds, prior=(0.0, 0.0, 0.0), converged=True, rms=1.0, threshold=0.1, before=None
):
    """``hold_unidentified`` on free parameters a, b, c whose relative standard errors are
    ``rounds[0]`` at the fit and ``rounds[k]`` (of the parameters still active) after the
    k-th solve again, which returns the solver "solver k"; ``before``: the parameters held
    before. Returns (the end, the fit it started from, the active flags and theta of each
    solve again)."""
    stats = [
        SimpleNamespace(
            relative_std=np.array(r),
            relative_std_gn=np.array(r) / 2,
            collinearity=np.full(len(r), 0.9),
        )
        for r in rounds
    ]
    resolved = []
    cost = SimpleNamespace(cost=0.0)  # the residual rms is ``rms`` whatever the cost

    def resolve(theta, active):
        resolved.append((active.tolist(), theta.tolist()))
        state = SimpleNamespace(active=active, theta=theta, evaluation=cost)
        return state, f"solver {len(resolved)}"

    monkeypatch.setattr(FitRun, "statistics", lambda run, gn, state: stats[len(resolved)])
    problem = SimpleNamespace(
        free=(0, 1, 2), free_names=("a", "b", "c"), prior_weight=np.array(prior)
    )
    ms = SimpleNamespace(residual_rms=lambda cost: rms)
    state = SimpleNamespace(
        active=np.ones(3, dtype=bool), theta=np.array([0.1, 0.2, 0.3]), evaluation=cost
    )
    stages = [SimpleNamespace(converged=converged)]
    options = FitOptions(identifiability_threshold=threshold)
    run = FitRun(problem, options, ms, None, None, None, None, 0.0, stages)
    given = Fitted(state, "solver 0", stats[0], {} if before is None else before)
    return holds.hold_unidentified(run, given, resolve), given, resolved


def _holds(monkeypatch, rounds, prior=(0.0, 0.0, 0.0), converged=True, rms=1.0):
    """(held, the active flags and theta of each solve again) of ``_hold``."""
    ended, _, resolved = _hold(monkeypatch, rounds, prior, converged, rms)
    return ended.held, resolved


def test_the_worst_parameter_is_held_first_and_the_rest_solved_again(monkeypatch):
    """c (200 %) is held first, at its initial value (theta 0); then b (30 % after that
    solve); a (5 %) stays free."""
    held, resolved = _holds(monkeypatch, [[0.05, 0.5, 2.0], [0.05, 0.3], [0.05]])
    assert list(held) == ["c", "b"]
    assert held["c"] == (2.0, 1.0, 0.9) and held["b"] == (0.3, 0.15, 0.9)
    assert resolved == [
        ([True, True, False], [0.1, 0.2, 0.0]),
        ([True, False, False], [0.1, 0.0, 0.0]),
    ]


def test_parameters_the_data_plainly_do_not_determine_are_held_together(monkeypatch):
    """Over 100 % (``StrategySettings.hopeless_std``) b and c are held at once with the worst,
    in one solve."""
    held, resolved = _holds(monkeypatch, [[0.05, 1.5, 2.0], [0.05]])
    assert set(held) == {"b", "c"}
    assert [active for active, _ in resolved] == [[True, False, False]]


def test_a_parameter_with_a_prior_is_never_held(monkeypatch):
    held, resolved = _holds(monkeypatch, [[0.05, 0.08, 5.0]], prior=(0.0, 0.0, 1.0))
    assert held == {} and resolved == []


@pytest.mark.parametrize(("rms", "holds"), [(1.2, True), (2.0, False)])
def test_an_unconverged_fit_holds_only_at_the_noise_level(monkeypatch, rms, holds):
    """Below ``StrategySettings.hold_misfit`` = 1.5 noise std a sloppy direction is the likely
    reason for the stall (holding helps); above it the errors mean nothing and nothing is
    held."""
    held, _ = _holds(monkeypatch, [[0.05, 0.05, 0.5], [0.05, 0.05]], converged=False, rms=rms)
    assert bool(held) is holds


def test_parameters_are_not_reported_held_when_holding_would_leave_nothing_free(monkeypatch):
    """All three over ``hopeless_std``: holding them would leave nothing to fit, so none is
    held (the parameters keep their fitted values, reported as poorly determined) and
    nothing is solved again."""
    ended, given, resolved = _hold(monkeypatch, [[2.0, 3.0, 4.0]])
    assert ended.held == {} and resolved == []
    assert ended.state is given.state


def test_the_last_free_parameter_is_not_held(monkeypatch):
    """c is held, then a and b would both be: they stay free."""
    held, resolved = _holds(monkeypatch, [[0.05, 0.5, 2.0], [1.5, 3.0]])
    assert list(held) == ["c"] and len(resolved) == 1


def test_a_parameter_is_held_by_its_place_among_those_still_free(monkeypatch):
    """a is held first; the statistics after that solve list b and c only, so c's 60 % is
    their second entry and it is the third free parameter that is held next."""
    held, resolved = _holds(monkeypatch, [[2.0, 0.05, 0.5], [0.05, 0.6], [0.05]])
    assert list(held) == ["a", "c"] and held["c"] == (0.6, 0.3, 0.9)
    assert [active for active, _ in resolved] == [[False, True, True], [False, True, False]]


def test_the_fit_ends_at_the_last_solve_again_with_its_statistics(monkeypatch):
    ended, given, resolved = _hold(monkeypatch, [[0.05, 0.5, 2.0], [0.05, 0.3], [0.05]])
    assert ended.solver == "solver 2" and ended.statistics.relative_std.tolist() == [0.05]
    assert ended.state.active.tolist() == resolved[-1][0]
    # The fit it started from is left as it was.
    assert given.state.active.all() and given.state.theta.tolist() == [0.1, 0.2, 0.3]


def test_parameters_held_before_stay_held(monkeypatch):
    """Held earlier (a previous stage's holds) and now c: both are reported, and the given
    fit's record of its holds is not changed."""
    before = {"d": (3.0, 1.5, 0.99)}
    ended, given, _ = _hold(monkeypatch, [[0.05, 0.05, 0.5], [0.05, 0.05]], before=before)
    assert ended.held == {"d": (3.0, 1.5, 0.99), "c": (0.5, 0.25, 0.9)}
    assert given.held == {"d": (3.0, 1.5, 0.99)}


@pytest.mark.parametrize(("threshold", "held"), [(0.6, []), (0.4, ["c", "b"])])
def test_the_identifiability_threshold_is_the_options(monkeypatch, threshold, held):
    ended, _, _ = _hold(monkeypatch, [[0.05, 0.5, 0.55], [0.05, 0.5], [0.05]], threshold=threshold)
    assert list(ended.held) == held


def test_with_a_prior_on_the_worst_the_next_worst_is_held(monkeypatch):
    """c (500 %, a prior) is judged identified by its prior: not held, nor swept up with the
    parameters above ``StrategySettings.hopeless_std``; b (50 %) is held."""
    held, resolved = _holds(monkeypatch, [[0.05, 0.5, 5.0], [0.05, 5.0]], prior=(0.0, 0.0, 1.0))
    assert list(held) == ["b"]
    assert [active for active, _ in resolved] == [[True, False, True]]
