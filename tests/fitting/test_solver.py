"""The condensed Gauss-Newton solver's merit function and its overflow verdict
(``fitting.solver``)."""

import dataclasses
import warnings

import numpy as np
import pytest

from hframe_id.fitting.gauss_newton_settings import GaussNewtonSettings
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.fitting.solver import (
    GaussNewton,
    SolverState,
    _penalty_parameter,
    _Walk,
    _watchdog_verdict,
)
from hframe_id.fitting.substep_plan import stopped_message
from hframe_id.fitting.trust_region import trust_region_step


@pytest.mark.parametrize("rho", [GaussNewtonSettings.merit_rho, 0.5])
def test_penalty_parameter_makes_every_full_step_predict_a_decrease(rho):
    for change, l1 in ((10.0, 1.0), (1e9, 3.0), (-5.0, 2.0), (0.5, 4.0)):
        mu = _penalty_parameter(1.0, change, l1, rho)
        assert mu >= 1.0
        assert mu * l1 - change >= rho * mu * l1 - 1e-9 * abs(change)


def test_the_watchdog_shrinks_the_region_on_every_step_it_refuses():
    """An exact stage's watchdog accepts any finite merit in its first (free) steps, then a
    merit below factor x the best; the region shrinks (ratio < 0.25, ``_adapt_region``) on
    an increase and on every refusal, whatever the step's own ratio."""
    factor = GaussNewtonSettings.watchdog_factor
    # Refused past the free steps: above factor x best, though it halves the current merit.
    assert _watchdog_verdict(0.52, 5e11, 1e12, 1e10, False, factor)[1] is False
    assert _watchdog_verdict(0.52, 5e11, 1e12, 1e10, False, factor)[0] < 0.25
    assert _watchdog_verdict(0.9, 5e11, 1e12, 1e10, False, factor)[0] < 0.25
    # The same step in the free steps is accepted, the region kept.
    assert _watchdog_verdict(0.52, 5e11, 1e12, 1e10, True, factor) == (0.52, True)
    # Within factor x best: a decrease keeps the region (ratio at least 0.5), an increase
    # shrinks it, both accepted.
    assert _watchdog_verdict(0.1, 9.0, 10.0, 1.0, False, factor) == (0.5, True)
    assert _watchdog_verdict(-2.0, 9.0, 8.0, 1.0, False, factor) == (-2.0, True)
    # A non-finite merit is refused, its ratio left to ``_adapt_region``.
    assert _watchdog_verdict(0.7, np.inf, 8.0, 1.0, True, factor) == (0.7, False)


def test_a_step_the_watchdog_refuses_ends_the_trial_instead_of_repeating_it(shooting_setup):
    """A walk whose current merit is far above factor x its best (as after the penalty
    parameter rose on issue 25's test plant 1262; here a best of 0): every step is
    refused. Each refusal must change the region or the damping, so the trial ends, not
    accepted, after at most one step per factor of 10 between the node damping and its cap
    (15 with the defaults); it repeated the same step for 35 min."""
    problem, ms, nodes, _ = shooting_setup
    theta = np.full(ms.nf, 0.3)
    ev = ms.evaluate(nodes, theta, problem.smoothing)
    state = SolverState(nodes.copy(), theta, np.ones(ms.nf, dtype=bool), evaluation=ev)
    gn = GaussNewton(ms)
    gn.set_smoothing(problem.smoothing)
    walk = _Walk(ms, gn.links, None, 0.5, False)
    # No merit is below factor x 0: every step refused. (A raise of the penalty parameter
    # would merit the best again from its evaluation: mu is set above any raise.)
    walk.best, walk.mu = (0.0, nodes, theta, ev), 1e15
    evaluate, calls = gn._evaluate, []

    def counted(*args, **kwargs):
        calls.append(1)
        assert len(calls) <= 50, "the refused step is tried again and again"
        return evaluate(*args, **kwargs)

    gn._evaluate = counted
    trial = gn._trial(walk, state, problem.smoothing, gn.settings.free_steps + 1)
    assert not trial.accepted
    settings = gn.settings
    assert len(calls) <= 1 + np.log10(settings.max_node_damping / settings.node_damping)


def _first_trial(ms, nodes, ev, smoothing):
    """The Gauss-Newton stage's first step from ``ev`` (at theta = 0), numpy warnings raised
    as errors (the fit's command line showed every numpy RuntimeWarning)."""
    theta = np.zeros(ms.nf)
    gn = GaussNewton(ms)
    gn.set_smoothing(smoothing)
    state = SolverState(nodes, theta, np.ones(len(theta), dtype=bool), evaluation=ev)
    walk = _Walk(ms, gn.links, None, 0.5, False)
    walk.best = (walk.merit(ev, nodes), nodes, theta, ev)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return gn._trial(walk, state, smoothing, 1)


def test_overflowing_sensitivities_stop_the_step_without_numpy_warnings(shooting_setup):
    """Sensitivities too large to square (a parameter run far off) make the linearisation
    non-finite: the step says so (``overflowed``, which ends the stage with that reason)
    and nothing is printed."""
    problem, ms, nodes, _ = shooting_setup
    ev = ms.evaluate(nodes, np.zeros(len(problem.free)), problem.smoothing)
    huge = dataclasses.replace(ev, jac_theta=ev.jac_theta * 1e300)
    trial = _first_trial(ms, nodes, huge, problem.smoothing)
    assert trial.overflowed and not trial.accepted


def test_a_point_refused_for_its_stiffness_stops_the_stage_saying_why(shooting_setup):
    """At a point whose friction at rest needs more RK4 substeps for stability than
    max_substeps, the evaluation is refused (``MultipleShooting.evaluate``): no step can be
    computed there, and the stage's reason names the count needed and the cap."""
    problem, ms, nodes, _ = shooting_setup
    cap = 10  # Table 4.2 needs 16-17 at rest (4.5e4 1/s at 1 ms)
    refusing = MultipleShooting(
        problem, transcription=dataclasses.replace(ms.transcription, max_substeps=cap)
    ).uniform()
    ev = refusing.evaluate(nodes, np.zeros(len(problem.free)), problem.smoothing)
    trial = _first_trial(refusing, nodes, ev, problem.smoothing)
    assert trial.overflowed and not trial.accepted
    needed = refusing.substep_plan(problem.p_initial, problem.smoothing)["stiff"]
    assert needed > cap
    message = stopped_message(ev.n_substeps[1], cap)
    assert f"needs {needed} substeps per sample, more than max_substeps {cap}" in message


def test_a_gradient_whose_square_overflows_still_gets_a_step_on_the_region():
    """A finite gradient of 1e200 (residuals far off at a sane curvature): its norm squared
    overflows. The region's bisection used that inf and returned a zero step; the step is
    on the region's edge, pointing down the gradient, and nothing is printed."""
    h = np.diag([1.0, 4.0])
    g = np.array([1e200, -3e200])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        d, full = trust_region_step(h, g, 0.5)
    assert not full
    # The bisection stops at a relative width of 1e-6 in mu: the step's norm within that.
    assert np.linalg.norm(d) == pytest.approx(0.5, rel=1e-5)
    assert g @ d < 0


def test_sensitivities_that_overflow_once_weighted_print_no_numpy_warning(
    shooting_setup, monkeypatch
):
    """The weighted Jacobian of sensitivities near the float range is inf (the solver's
    verdict on the step, above), computed without numpy RuntimeWarnings: a realistic
    six-step fit printed them in `make bench`."""
    problem, ms, nodes, _ = shooting_setup
    integrate = ms._integrate_split

    def huge(todo, nodes_, p, smoothing, plan, hint, out):
        stiff = integrate(todo, nodes_, p, smoothing, plan, hint, out)
        with np.errstate(over="ignore"):
            out["sens"] *= 1e306
        return stiff

    monkeypatch.setattr(ms, "_integrate_split", huge)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ev = ms.evaluate(nodes, np.zeros(len(problem.free)), problem.smoothing)
    assert not np.all(np.isfinite(ev.jac_theta))


def test_an_interrupt_ends_an_exact_stage_with_its_message(shooting_setup):
    """``GaussNewton.run``'s ``interrupt`` is asked after each accepted iteration once there
    are ``cost_window`` of them, with the cost's decrease over the last ``cost_window``; what
    it returns ends the stage, converged, at the last accepted point."""
    problem, ms, nodes, _ = shooting_setup
    window = GaussNewtonSettings.cost_window
    asked = []

    def interrupt(ev, decrease):
        asked.append((ev.cost, decrease))
        return "the next round gains more" if len(asked) == 2 else None

    theta = np.full(ms.nf, 0.3)  # every free parameter x 1.35: a walk of many iterations
    state = SolverState(nodes.copy(), theta, np.ones(ms.nf, dtype=bool))
    gn = GaussNewton(ms)
    report = gn.run(state, "exact", problem.smoothing, 100, 1e-12, 1e-3, interrupt=interrupt)
    assert report.converged and report.message == "the next round gains more"
    # Asked first after iteration ``window`` (at the earliest: only with the defects closed).
    assert report.iterations >= window + 1
    assert report.cost == asked[-1][0] == state.evaluation.cost
    assert all(np.isfinite(decrease) for _, decrease in asked)


def test_trial_steps_are_judged_on_residuals_and_linearized_only_where_accepted(
    shooting_setup, monkeypatch
):
    """A trial step is judged by its merit alone: it is integrated without sensitivities
    (4-5x cheaper on a stick-slip plant's six steps), and the accepted point once more with them,
    for the next linearization. The walk is the one that evaluates every trial with its
    sensitivities: the residual-only trajectory is bitwise the one with sensitivities."""
    problem, ms, nodes, _ = shooting_setup
    theta = np.full(ms.nf, 1.0)  # every free parameter x 2.7: a walk with rejected trials
    calls = []
    evaluate = MultipleShooting.evaluate

    def counted(self, *args, derivatives=True, **kwargs):
        calls.append(derivatives)
        return evaluate(self, *args, derivatives=derivatives, **kwargs)

    def walk(always_linearize: bool):
        calls.clear()
        state = SolverState(nodes.copy(), theta.copy(), np.ones(ms.nf, dtype=bool))
        gn = GaussNewton(ms)
        accept = gn._accept
        gn._accept = lambda *args: (calls.append("accepted"), accept(*args))
        if always_linearize:
            monkeypatch.setattr(MultipleShooting, "evaluate", evaluate)
            gn._evaluate = lambda st, n, t, s, derivatives=True: GaussNewton._evaluate(
                gn, st, n, t, s
            )
        else:
            monkeypatch.setattr(MultipleShooting, "evaluate", counted)
        report = gn.run(state, "exact", problem.smoothing, 30, 1e-12, 1e-3, watchdog=False)
        return report, state, list(calls)

    report, state, calls = walk(always_linearize=False)
    accepted, trials = calls.count("accepted"), calls.count(False)
    assert 0 < accepted < trials, "the walk must reject a trial for this test to mean anything"
    # One linearization at the start and one per accepted step, each right before its
    # acceptance; every trial residual-only.
    assert calls.count(True) == 1 + accepted and calls[0] is True
    assert all(calls[i - 1] is True for i, c in enumerate(calls) if c == "accepted")
    reference, reference_state, _ = walk(always_linearize=True)
    assert report.cost == reference.cost and report.iterations == reference.iterations
    assert np.array_equal(state.theta, reference_state.theta)
    assert np.array_equal(state.evaluation.jac_theta, reference_state.evaluation.jac_theta)
