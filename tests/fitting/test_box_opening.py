"""How far a fit's default box opens (``fitting.box_opening``), on hand-made results."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from hframe_id.fitting import FitOptions, local_fit
from hframe_id.fitting.box_opening import OPENED_BOX_STAGE, BoxOpening, opened_box_report
from hframe_id.fitting.solver import SolverState


def _ended(boxed, b_estimate=0.1):
    """A result on the default box with ``boxed``: ``b`` and ``c`` friction terms
    (nonnegative), ``b`` at ``b_estimate`` from a start of 1; ``m`` a mass (positive) at 9
    from 1."""
    spec = [
        SimpleNamespace(name="b", kind="nonnegative"),
        SimpleNamespace(name="c", kind="nonnegative"),
        SimpleNamespace(name="m", kind="positive"),
    ]
    estimates = {
        "b": SimpleNamespace(estimate=b_estimate, initial=1.0),
        "c": SimpleNamespace(estimate=1.0, initial=1.0),
        "m": SimpleNamespace(estimate=9.0, initial=1.0),
    }
    last = SimpleNamespace(smoothing=(0.0, 0.0), cost=12.5, max_defect=1e-9)
    return SimpleNamespace(
        diagnostics=SimpleNamespace(at_default_box=tuple(boxed)),
        problem=SimpleNamespace(model=SimpleNamespace(parameters=spec), free_names=("b", "c", "m")),
        estimates=estimates,
        stages=[last],
    )


def test_friction_below_its_start_opens_every_friction_term_to_zero_without_a_squaring():
    box = BoxOpening(10.0, 2)
    opened = box.opened(FitOptions(bound_factor=10.0), _ended(("b",)))
    assert opened.zero_reachable == ("b", "c")
    assert opened.bound_factor == 10.0


def test_friction_above_its_start_or_a_mass_squares_the_factor_until_the_widenings_are_used():
    box = BoxOpening(10.0, 2)
    options = FitOptions(bound_factor=10.0)
    factors = []
    while (options := box.opened(options, _ended(("m",)))) is not None:
        factors.append(options.bound_factor)
    assert factors == [100.0, 1e4]
    assert box.squarings(FitOptions(bound_factor=1e4)) == 2
    above = box.opened(FitOptions(bound_factor=10.0), _ended(("b",), b_estimate=10.0))
    assert (above.bound_factor, above.zero_reachable) == (100.0, ())


def test_nothing_opens_for_a_fit_off_the_box_or_friction_already_at_zero():
    box = BoxOpening(10.0, 2)
    assert box.opened(FitOptions(bound_factor=10.0), _ended(())) is None
    # Friction already reaches 0 and the factor is used up: nothing left to open.
    spent = FitOptions(bound_factor=1e4, zero_reachable=("b", "c"))
    assert box.opened(spent, _ended(("b", "m"))) is None


def test_the_opened_box_stage_says_what_ended_on_it_and_what_opened():
    before = FitOptions(bound_factor=10.0)
    after = FitOptions(bound_factor=100.0, zero_reachable=("b", "c"))
    report = opened_box_report(_ended(("b", "m")), before, after)
    assert report.name == OPENED_BOX_STAGE and report.converged and report.iterations == 0
    assert report.cost == 12.5
    assert report.message.startswith("b, m ended on the default box")
    assert "friction may reach 0 (b, c)" in report.message
    assert "bound factor 10 -> 100" in report.message


@pytest.mark.parametrize("wall", [False, True])
def test_a_fit_goes_on_in_the_opened_box_until_nothing_is_left_to_open(monkeypatch, wall):
    """``local_fit.OpenedBox``: each continuation in a box opened further, then the last
    solve from rest (a no-op once it has run); none against the stiffness wall."""
    boxes = iter([("m",), ("m",), ("m",)])
    run = SimpleNamespace(
        options=FitOptions(bound_factor=10.0),
        result=lambda best: _ended(next(boxes)),
        against_the_wall=lambda theta: ("J_M1",) if wall else (),
    )
    at = local_fit.Standing(
        run, [], np.ones(2), best=SimpleNamespace(state=SimpleNamespace(theta=0))
    )
    factors = []

    def continued(options, at, ended):
        factors.append(options.bound_factor)
        return local_fit.Standing(replace_options(at.run, options), [], np.ones(2), best=at.best)

    def replace_options(run, options):
        return SimpleNamespace(**{**vars(run), "options": options})

    monkeypatch.setattr(local_fit, "_continued_in", continued)
    monkeypatch.setattr(local_fit, "ReplayedRest", lambda: lambda at: at)
    local_fit.OpenedBox(BoxOpening(10.0, 2))(at)
    assert factors == ([] if wall else [100.0, 1e4])


def test_the_noise_rounds_of_every_box_are_counted_once_the_box_opens(monkeypatch):
    """``local_fit._continued_in``: the rounds in the opened box start their own count (and
    budget), and the rounds of the boxes before it are kept for the report
    (``Standing.earlier_rounds``)."""
    problem = SimpleNamespace(free=(0, 1), theta_of=lambda params: np.zeros(2), initial=None)
    monkeypatch.setattr(local_fit, "build_problem", lambda recordings, initial, options: problem)
    monkeypatch.setattr(local_fit, "MultipleShooting", lambda problem, transcription: "ms")
    monkeypatch.setattr(local_fit, "opened_box_report", lambda *args: "opened")
    monkeypatch.setattr(
        local_fit,
        "estimate_noise",
        lambda run, state, recordings, std: (run, state, "gn", 3, "settled"),
    )
    monkeypatch.setattr(local_fit.FitRun, "statistics", lambda self, gn, state: "statistics")
    run = local_fit.FitRun(problem, FitOptions(), "ms", None, None, None, None, 0.0)
    state = SolverState(np.zeros((1, 2)), np.ones(2), np.zeros(2, dtype=bool))
    best = local_fit.Fitted(state, "gn", "statistics")
    at = local_fit.Standing(run, [], np.ones(2), best=best, rounds=4, earlier_rounds=10)
    ended = SimpleNamespace(parameters=None)
    opened = FitOptions(bound_factor=100.0).for_model("hframe-8")
    after = local_fit._continued_in(opened, at, ended)
    assert (after.rounds, after.earlier_rounds) == (3, 14)
    assert after.run.stages == ["opened"] and after.best.state.active.all()
