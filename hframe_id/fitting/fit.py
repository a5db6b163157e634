"""``fit_recordings``: data + model + free parameters -> estimates with honest uncertainty.

The chain (PyBOP-style plain objects): recordings -> :class:`FitProblem` (checked) ->
:class:`MultipleShooting` (transcription) -> :class:`GaussNewton` (solver) ->
:mod:`statistics` (covariance, identifiability) -> :class:`FitResult`. One solve inside one
box of bounds is :func:`hframe_id.fitting.local_fit.fit_in_box` (its stages); this module
is the strategy around it, what makes a success mean the parameters are right:

1. the box: a fit that ends on its default box (drawn around the start) goes on with the
   box opened (``box_opening``: friction down to zero first), and a parameter still on it is
   either one the data bound on one side only (``open_ended``) or a failure saying the box
   decided;
2. known points: the fit is judged against every point it knows (the start, the
   equation-error estimate, the model's reference files, the user's) by the criterion of its
   written file, and continues from a better one (``known_points``);
3. a multistart portfolio on request (``FitOptions.starts``, ``multistart``);
4. the structure: a model that nests in a larger one (hframe-8 in hframe-8-current-limit) is
   fitted as that one too, and the data choose (``structure_choice``).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import replace

import numpy as np

from hframe_id.errors import FitError
from hframe_id.fitting.box_opening import BoxOpening
from hframe_id.fitting.dataset import Dataset, check_excitation
from hframe_id.fitting.estimates import at_bound_clause
from hframe_id.fitting.known_points import (
    Criterion,
    KnownPointsReport,
    Simulations,
    judged_starts,
    known_points,
    replayed_starts,
)
from hframe_id.fitting.local_fit import fit_in_box
from hframe_id.fitting.multistart import judged, seeded_starts
from hframe_id.fitting.open_ended import open_ends
from hframe_id.fitting.options import FitOptions
from hframe_id.fitting.progress import labelled, progress_sink
from hframe_id.fitting.resolution import LIKELIHOOD_RATIO_95
from hframe_id.fitting.result import FitResult
from hframe_id.fitting.start_screen import (
    Beginning,
    equation_error_theta,
    known_candidates,
    screen_start,
)
from hframe_id.fitting.stiffness_wall import at_the_wall
from hframe_id.fitting.structure_choice import check_nesting, with_structure_choice
from hframe_id.models import build_model
from hframe_id.parameters import ParameterSet
from hframe_id.recordings.recording import Recording


def fit_recordings(
    recordings: list[Recording], initial: ParameterSet, options: FitOptions | None = None
) -> FitResult:
    """Fit a model's parameters to one or more recordings jointly (multiple shooting).

    Each channel is weighted by the sensor's noise (``options.channel_std`` or the rig's
    noise model) or, where the model cannot follow the data at that level (``options.noise``,
    see ``noise_rounds.estimate_noise``), by noise levels estimated from the residuals.

    Parameters
    ----------
    recordings : experiments of one rig and model variant (``Recording``).
    initial : starting parameter values (and the values of the fixed parameters).
    options : what is free, bounds, weights, transcription and solver settings.

    Returns
    -------
    FitResult. ``success`` is False (with the reason in ``message``) if a stage did not
    converge or a free parameter ended at a bound.

    Raises
    ------
    FitError : before any solving, for a problem that cannot be fitted (mixed rigs or
        variants, unknown parameter names, bounds excluding the initial value, too few
        valid samples, no recording that excites the model).
    """
    options = (options or FitOptions()).for_model(initial.variant)
    check_nesting(initial.variant, options)
    _check_excitation(recordings, initial.variant)
    start = time.perf_counter()
    simulations = Simulations()
    screen = screen_start(recordings, initial, options, simulations)
    if options.starts > 1:
        result = _portfolio(recordings, screen.parameters, options, screen.criterion)
        result = _off_the_wall(recordings, screen.parameters, options, screen.criterion, result)
    else:
        result = _fit_from(recordings, screen.parameters, options, screen.criterion)
    if screen.moved:
        result = replace(result, message=f"{result.message}; {screen.statement()}")
    result = result.with_diagnostics(start_screen=screen)
    # The known points are judged by simulation from the recordings' start: the criterion of
    # an output-error fit. A prediction-error fit (continuity "none", for plants whose
    # simulation drifts) has no such criterion to compare by.
    if options.continuity == "exact":
        judged = _never_worse_than_known(recordings, initial, options, result, screen, simulations)
        result = _explaining_the_data(recordings, judged, simulations)
        result = with_structure_choice(recordings, initial, options, result, fit_recordings)
    result = replace(result, wall_time_s=time.perf_counter() - start)
    return result


def _check_excitation(recordings, variant: str) -> None:
    """``FitError`` before any work if no recording excites the model (``dataset.
    check_excitation``), a warning naming each one at rest among others that do. Records
    whose channels are not the model's are left to the problem's own checks, which name
    what does not match."""
    model = build_model(variant)
    try:
        experiments = [Dataset.from_recording(model, rec) for rec in recordings]
    except FitError:
        return
    for name in check_excitation(experiments):
        warnings.warn(
            f"{name}: inputs constant and the plant at rest throughout; it tells nothing of "
            "the parameters",
            stacklevel=3,
        )


def _explaining_the_data(
    recordings, result: FitResult, simulations: Simulations | None = None
) -> FitResult:
    """``result`` with its written file's criterion replayed as ``validate`` replays it
    (``known_points.replayed_starts``: a record at rest from the replay's rest state; runs
    shared through ``simulations``) in its known-points report, and failed if it succeeded
    without that replay simulating the records better, by more than ``LIKELIHOOD_RATIO_95``
    and under the fit's noise levels (``known_points.Criterion.against_unforced``), than
    both the same model from the same states with its inputs held at their start (else the
    inputs do not drive what the outputs show under it) and each channel held at its mean
    (else it reproduces the records no better than a flat line). A failed fit says the same
    of the point it ended at. A fit of records whose inputs do not drive what the outputs
    show (a red-team record with its voltages zeroed and its motion kept) ended "success",
    every parameter not identified; judged from its own estimated initial states it still
    did (belts started stretched move the model without input), as did a one-axis fit of
    current-limited pulses whose replay from rest was worse than a flat line
    (docs/studies/2026-11-26-replayed-verdict.md). The two comparisons part where friction
    holds a plant nearly still: test plant 1314's replay beats its model unforced and not the
    held means, which no point of the model tried comes near, the plant's own reduction
    included (docs/studies/2026-11-29-held-still-and-unforced.md)."""
    criterion = Criterion.of(result, recordings, simulations)
    starts = replayed_starts(result)
    replayed = criterion(result.parameters, (starts,))
    report = replace(result.diagnostics.known_points, replayed=replayed)
    result = result.with_diagnostics(known_points=report)
    model, still, held = criterion.against_unforced(result.parameters, starts)
    if model < min(still, held) - LIKELIHOOD_RATIO_95:
        return result
    replay = "simulated from the records' start as validate replays it"
    levels = "chi^2 / 2 under the fit's noise levels"
    if model >= still - LIKELIHOOD_RATIO_95:
        why = (
            f"{replay} is no closer to them than with its inputs held at their start ({levels}: "
            f"{model:.6g} against {still:.6g}); the inputs do not drive what the outputs show "
            "under this model"
        )
    else:
        why = (
            f"{replay} is no closer to them than each channel held at its mean ({levels}: "
            f"{model:.6g} against {held:.6g}), though closer than with its inputs held at their "
            f"start ({still:.6g}); the records show motion this model does not reproduce"
        )
    if not result.success:  # said of the point it ended at too
        return replace(result, message=f"{result.message}; it explains none of the data: {why}")
    return replace(
        result,
        success=False,
        message=f"the fitted model explains none of the data: its file {why}; {result.message}",
    )


def _portfolio(
    recordings, initial: ParameterSet, options: FitOptions, judge: Criterion | None = None
) -> FitResult:
    """The fit from ``initial`` (``judge``: as ``_fit_widening``) and from
    ``options.starts - 1`` seeded draws around it (``multistart``), one after another; the
    best successful one by its file's criterion (the first's if none succeeded), with every
    start's outcome in ``diagnostics.starts``."""
    progress = progress_sink(options)
    first = _fit_widening(recordings, initial, options, judge)
    problem = first.problem
    kinds = {spec.name: spec.kind for spec in problem.model.parameters}
    draws = seeded_starts(
        initial,
        problem.free_names,
        kinds,
        options.starts,
        options.start_seed,
        options.bounds,
    )
    results = [(draws[0][0], first)]
    for label, start in draws[1:]:
        named = replace(options, progress=labelled(progress, label)) if progress else options
        results.append((label, _fit_widening(recordings, start, named).started_from(initial)))
    outcomes = judged(results, Criterion.of(first, recordings))
    k = min(range(len(outcomes)), key=lambda i: outcomes[i].criterion)
    return results[k][1].with_diagnostics(starts=tuple(outcomes))


def _fit_from(
    recordings, initial: ParameterSet, options: FitOptions, judge: Criterion | None = None
) -> FitResult:
    """The fit from ``initial`` with the box opened while it ends on it (``_fit_widening``)
    and restarted off the stiffness wall where it ends against it (``_off_the_wall``): every
    fit from one start, a continuation from a known point too. (Test plant 1326 of issue 25:
    its continuation from a known point stopped its noise rounds at the wall, the last one
    ended for re-weighting with the levels unsettled, and was called a success; held out,
    19 x the plant's reduction: docs/studies/2026-11-29-every-fit-off-the-wall.md.)"""
    result = _fit_widening(recordings, initial, options, judge)
    return _off_the_wall(recordings, initial, options, judge, result)


def _fit_widening(
    recordings, initial: ParameterSet, options: FitOptions, judge: Criterion | None = None
) -> FitResult:
    """The fit within the default box, the box opened while it ends on it
    (``box_opening.BoxOpening``). A fit that ends on the box after its noise rounds
    continues from its end in the opened box (``local_fit.OpenedBox``); one whose first solve
    ends on it returns before the rounds and is repeated here, in the opened box. Still on the
    box with nothing left to open: open-ended parameters (``open_ended``), or a failure saying
    the box decided.

    ``judge``: ``initial`` is the start screen's point (``start_screen``, its criterion);
    a repeated fit then begins from where the last one ended on the box if the judge finds
    that better (``start_screen.Beginning``), else from ``initial`` again. (Restarting from
    the last end unjudged was measured worse: the linear hframe-20 plant then ended with
    F_c_bridge on the box, 1.53 x the reduction's training cost, in 77 s against 36 s.
    Restarting from ``initial`` always lost a first fit that had found the rig: the shipped
    2 V steps began from the equation-error estimate, ended with B_M1 on its box at the
    rig's value, and the refits from there ended at a wrong optimum, docs/studies/.)"""
    box = BoxOpening.of(options)
    begin = Beginning(initial)
    while True:
        result = fit_in_box(recordings, begin.parameters, options, box, screened=bool(judge))
        opened = box.opened(result.options, result)
        if opened is None:
            break
        if judge:
            begin = begin.or_better(result.parameters, judge)
        options = replace(
            options, bound_factor=opened.bound_factor, zero_reachable=opened.zero_reachable
        )
    if begin.parameters is not initial:
        result = result.started_from(initial)
        result = replace(result, message=f"{result.message}; {begin.statement}")
    boxed = result.diagnostics.at_default_box
    if not (boxed and result.success):
        return result
    ends = open_ends(result, recordings, boxed)
    if all(end.open for end in ends):
        return _with_open_ends(result, ends)
    return replace(
        result,
        success=False,
        message=f"the default box decided the answer: {', '.join(boxed)} ended on a "
        f"bound of x/÷{result.options.bound_factor:g} of the start after "
        f"{box.squarings(result.options)} widenings (the data push them further: a start "
        "closer to the rig, or --bounds, decides instead; "
        + "; ".join(end.statement() for end in ends)
        + "); "
        + result.message,
    )


def _off_the_wall(
    recordings, start: ParameterSet, options: FitOptions, judge, result: FitResult
) -> FitResult:
    """``result``, or where it ended against the stiffness wall (``stiffness_wall``: some
    coordinate's Coulomb rate at rest so high that ``max_substeps`` caps its integration), a
    fit restarted once from its end with the parameters that set those rates
    (``wall_parameters``) back at ``start``'s values, the better of the two by the first's
    criterion. Still against the wall, a failure saying so: ``max_substeps``, not the data,
    decided those parameters. (The heavy dev plant's fit walked both motor inertias down to
    the wall, 1.8e-6 kg m^2, held-out motor-angle rms 4.4 x the reduction's; restarted, it
    ends at 0.54 x: docs/studies/2026-11-27-the-stiffness-wall-as-a-constraint.md.) A
    prediction-error fit (continuity "none") has no simulation criterion to judge a restart
    by: it only says so."""
    names = _at_the_wall(result, recordings)
    if names and options.continuity == "exact":
        moved = {n: float(start.values[n]) for n in names}
        progress = progress_sink(options)
        label = "restart off the stiffness wall"
        named = replace(options, progress=labelled(progress, label)) if progress else options
        again = _fit_widening(recordings, result.parameters.replace_values(**moved), named, judge)
        first, second = judged(
            [("fit", result), ("restart", again)], Criterion.of(result, recordings)
        )
        restarted = (
            f"restarted with {', '.join(names)} at the start's values after ending against "
            f"the stiffness wall (criterion {second.criterion:.6g} against {first.criterion:.6g})"
        )
        if second.criterion < first.criterion:
            result = again.started_from(result.initial)
        result = replace(result, message=f"{result.message}; {restarted}")
        names = _at_the_wall(result, recordings)
    if not names:
        return result
    wall = (
        f"{', '.join(names)} ended where the friction at rest is so stiff that a stable "
        f"integration needs more substeps than max_substeps {options.max_substeps} allows "
        "with its safety margin"
    )
    if not result.success:
        return replace(result, message=f"{result.message}; {wall}")
    return replace(
        result,
        success=False,
        message=f"max_substeps decided the answer: {wall} (the data pull them further; a "
        f"start closer to the rig, or fixing them, decides instead); {result.message}",
    )


def _at_the_wall(result: FitResult, recordings) -> tuple[str, ...]:
    """``stiffness_wall.at_the_wall`` at ``result``'s end point."""
    model = result.problem.model
    p = np.array([result.parameters.values[spec.name] for spec in model.parameters])
    return at_the_wall(result.problem, p, result.options, recordings[0].sample_period_s)


def _with_open_ends(result: FitResult, ends) -> FitResult:
    """``result`` with each of ``ends`` (``open_ended.OpenEnd``, all open) reported
    open-ended. Their interval is the whole physical range, 0 (minus infinity for a real
    parameter) to infinity: the data bound them on one side only, and the scan's finite end
    is the held slice's (the others at their fitted values), narrower than the profile's, so
    it is stated in the message, not given as a confidence bound."""
    kinds = {spec.name: spec.kind for spec in result.problem.model.parameters}
    estimates = dict(result.estimates)
    for end in ends:
        floor = -math.inf if kinds[end.name] == "real" else 0.0
        estimates[end.name] = replace(
            estimates[end.name], ci95=(floor, math.inf), open_ended=end.direction
        )
    at_bound = [n for n, est in estimates.items() if est.at_bound]
    still = [n for n in at_bound if not estimates[n].open_ended]
    message = result.message.replace(at_bound_clause(at_bound), at_bound_clause(still))
    message += "; open-ended: " + "; ".join(end.statement() for end in ends)
    return replace(result, estimates=estimates, message=message)


def _known_candidates(initial: ParameterSet, options: FitOptions, result, screen):
    """(label, parameter set) of the points a fit must not end worse than
    (``start_screen.known_candidates``): those the start screen judged (``screen``), where it
    ran; else the same points of ``result``'s problem."""
    if screen.candidates:
        return list(screen.candidates)
    regressed = result.equation_error
    if regressed is None:
        regressed = equation_error_theta(result.problem, options)
    return list(known_candidates(initial, result.problem, options, regressed))


def _never_worse_than_known(
    recordings, initial, options, result, screen, simulations: Simulations | None = None
) -> FitResult:
    """The fit judged against the points it knows (``known_points``) by the criterion of its
    written file (a free-run simulation of each record, ``known_points.Criterion``): ended
    worse than one, it continues from the best of them; worse still, it fails saying so. A
    fit that failed continues from each point it knows other than its start (where it has
    already failed), best first, until a continuation succeeds no worse than the failed
    fit's end and than the point it started from. ``simulations``: the fit's free runs
    (``known_points.Simulations``), shared with the start screen."""
    criterion = Criterion.of(result, recordings, simulations)
    # Every point, the fit too, from the fit's initial states, and for a failed fit also from
    # the replay's rest state, which ``validate`` starts the written file from
    # (``judged_starts``).
    starts = judged_starts(result)
    # A failed fit's end point is a point it knows too: a continuation must beat it (dev
    # plant 10: a fit failed on the box, continued from the equation-error estimate, ended
    # 300 x the reduction's training criterion; the failed fit's point simulated better).
    own = criterion(result.parameters, starts)
    candidates = _known_candidates(initial, options, result, screen)
    if not result.success:
        candidates = [(label, params) for label, params in candidates if label != "the start"]
    points = known_points(candidates, criterion, starts)
    report = KnownPointsReport(criterion.name, own, {p.label: p.criterion for p in points})
    # Differences under LIKELIHOOD_RATIO_95 are not significant at 95 %: such a point is not
    # better, and a continued fit that ends there has reached it.
    tried = (
        points
        if not result.success
        else [p for p in points[:1] if p.criterion < own - LIKELIHOOD_RATIO_95]
    )
    for point in tried:
        again = _fit_from(recordings, point.parameters, options).started_from(initial)
        continued = criterion(again.parameters, judged_starts(again)) if again.success else math.inf
        report = replace(report, continued={**report.continued, point.label: continued})
        if continued <= min(point.criterion, own) + LIKELIHOOD_RATIO_95:
            why = "failed" if not result.success else "ended worse"
            # The fit reported is the continued one, so the report's ``fit`` is its
            # criterion (it was the first fit's: not what the written file replays).
            return replace(
                again.with_diagnostics(known_points=replace(report, fit=continued)),
                message=f"{again.message}; continued from {point.label}, where the first fit {why}",
            )
    result = result.with_diagnostics(known_points=report)
    if not tried:
        return result
    if not result.success:
        return replace(
            result,
            message=result.message
            + "; fits continued from "
            + ", ".join(p.label for p in tried)
            + " failed or ended worse than it",
        )
    best = tried[0]
    continued = report.continued[best.label]
    return replace(
        result,
        success=False,
        message=f"did not converge: the fit ends worse than {best.label} ({criterion.name}: "
        f"{own:.6g} against {best.criterion:.6g}), and a fit continued from there ends at "
        f"{continued:.6g}",
    )
