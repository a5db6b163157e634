"""One fit inside one box of parameter bounds: the stages from a start to an optimum.

The strategy (:func:`strategy`: a list of stage objects, each called with where the fit
stands, :class:`Standing`, and returning where it stands after), in the order
:func:`fit_in_box` runs it (``docs/fitting.md`` has the measurements behind each choice):

1. equation error (in :class:`Attempts`, as 2 and 3): the models are linear in their
   parameters once multiplied by the mass matrix, so a regression on differentiated
   measurements gives a start in milliseconds (kept only if it fits the data better than
   the given start; :func:`_start`);
2. the output-error stages (:func:`hframe_id.fitting.output_error.solve`): multiple
   shooting on the windows where something moves, then on every window by the named solver;
3. statistics at the optimum; free parameters whose relative standard error exceeds the
   identifiability threshold are held at their initial value and stage 2 re-run
   (:func:`hframe_id.fitting.holds.hold_unidentified`); for each held parameter
   :mod:`hframe_id.fitting.design_advice` names the standard experiments that would
   identify it;
4. with a coordinate no output measures (one-axis: the idler), restarts along the springs
   that hold it (:class:`UnmeasuredRestarts`); a fit that may widen its box stops here if
   it ends on the default box (:class:`OnTheBox`);
5. noise levels estimated with the fit where the model cannot follow the data at the
   sensors' level (:class:`NoiseLevels`);
6. a last solve with each record at rest started as ``validate`` replays it
   (:class:`ReplayedRest`);
7. the misfit judgement of the end (:func:`_finished`).

A model with a coordinate no output measures first tries stages 1-3 with the node states
estimated at the parameters held (a state-estimation pre-pass), and if that does not
converge, again from the measured nodes.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np

from hframe_id.fitting.box_opening import OPENED_BOX_STAGE, BoxOpening, opened_box_report
from hframe_id.fitting.equation_error import equation_error_start
from hframe_id.fitting.fit_run import FitRun, Fitted
from hframe_id.fitting.held_uncertainty import include_held_uncertainty
from hframe_id.fitting.holds import hold_unidentified
from hframe_id.fitting.noise_rounds import (
    NoiseSettling,
    estimate_noise,
    noise_report,
    unweighted_residuals,
    warm_solve,
)
from hframe_id.fitting.options import FitOptions
from hframe_id.fitting.output_error import DEFERRED_STAGE, solve
from hframe_id.fitting.problem import build_problem
from hframe_id.fitting.progress import progress_sink
from hframe_id.fitting.replayed_rest import replays_rest, solve_from_replayed_rest
from hframe_id.fitting.result import FitResult
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.fitting.stages import equation_error_report
from hframe_id.fitting.unmeasured import restarts_along_unmeasured_springs, unmeasured_coordinates
from hframe_id.parameters import ParameterSet
from hframe_id.recordings.recording import Recording

#: Misfit limit of a fit weighted by the sensors' noise (residual rms in sensor std) when
#: ``FitOptions.max_misfit`` is not given: far above a correct fit on sim-rig data (1.0-1.3),
#: far below the wrong optima measured on one-axis data (10-45).
DEFAULT_MAX_MISFIT = 5.0


def fit_in_box(
    recordings: list[Recording],
    initial: ParameterSet,
    options: FitOptions,
    box: BoxOpening | None = None,
    screened: bool = False,
) -> FitResult:
    """``fit_recordings`` within the box of ``options`` (its bounds and bound factor): the
    stages of ``strategy`` in order, then the judgements of the end (``_finished``). With
    ``box`` (how far the default box may open), a first solve that ends on the default box
    returns before the noise rounds where ``box`` opens it (the fit is repeated in the opened
    box: measured on the lubricated plant of issue 25, the rounds took 25 of the 27 s of a
    fit whose six friction terms ended on the box after the first solve and stayed there),
    and a fit that ends on it after the rounds goes on in the opened box (:class:`OpenedBox`).
    ``screened``: ``initial`` is the start
    screen's choice (``start_screen``), which judged the equation-error estimate already, by
    the criterion the fit is judged by: the stages begin from ``initial`` as it is.
    A stage that ends against the stiffness wall ends the fit there: ``max_substeps``
    decided that point, and the strategy restarts off the wall (``fit._off_the_wall``)
    instead of running the later stages there, each integrating every window with
    ``max_substeps`` substeps."""
    run = _started_run(recordings, initial, options, regress=not screened)
    at = Standing(run, recordings, run.problem.channel_std.copy())
    for stage in strategy(run, box):
        at = stage(at)
        if at.ended is not None:
            return at.ended
        if at.run.against_the_wall(at.best.state.theta):
            break
    return _finished(at)


@dataclass
class Standing:
    """Where a fit in one box stands between its stages: its run (``FitRun``; the noise
    rounds and the last solve replace it), its best end so far (``Fitted``), the recordings,
    the sensors' noise std [SI] the run began with, the noise rounds run in its box and how
    settled their levels are, the rounds run in the boxes before it (``OpenedBox``; each box
    has its own ``max_noise_rounds``, the report counts them all), whether the output-error
    stages deferred to the rounds, and the result of a stage that ended the fit early
    (``ended``), else None."""

    run: FitRun
    recordings: list[Recording]
    sensor_std: np.ndarray
    best: Fitted | None = None
    rounds: int = 0
    earlier_rounds: int = 0
    settling: NoiseSettling | None = None
    deferred: bool = False
    ended: FitResult | None = None


class Stage(Protocol):
    """One stage of the strategy: where the fit stands after it."""

    def __call__(self, at: Standing) -> Standing: ...


def strategy(run: FitRun, box: BoxOpening | None) -> tuple[Stage, ...]:
    """The stages of a fit in one box, in order (module docstring). A model with a
    coordinate no output measures (one-axis: the idler) first attempts the fit with its
    node states estimated at the parameters held (converges from the truth on fresh plants,
    where the path from the measured nodes left it), then from the measured nodes (which fits
    the shipped pulses from Table 2.3, where the pre-pass path stalled), and restarts along
    the springs that hold it; with ``box``, a fit on the default box stops before the noise
    rounds (``fit._fit_widening`` repeats it in the opened box) or, ending on it after
    them, goes on in the opened box."""
    unmeasured = bool(unmeasured_coordinates(run.ms)) and run.options.state_prepass
    return (
        Attempts((True, False) if unmeasured else (False,)),
        *((UnmeasuredRestarts(),) if unmeasured else ()),
        *((OnTheBox(box),) if box else ()),
        NoiseLevels(),
        ReplayedRest(),
        *((OpenedBox(box),) if box else ()),
    )


@dataclass(frozen=True)
class Attempts:
    """The equation-error start, the output-error stages and the identifiability holds,
    once per entry of ``prepasses`` (with the state-estimation pre-pass or not), until one
    converges or defers to the noise rounds; else the attempt of lowest cost."""

    prepasses: tuple[bool, ...]

    def __call__(self, at: Standing) -> Standing:
        best = _best_attempt(at.run, list(self.prepasses))
        return replace(at, best=best, deferred=at.run.stages[-1].name == DEFERRED_STAGE)


class UnmeasuredRestarts:
    """Restarts along the springs at an unmeasured coordinate
    (``unmeasured.restarts_along_unmeasured_springs``), unless the stages deferred."""

    def __call__(self, at: Standing) -> Standing:
        if at.deferred:
            return at
        return replace(at, best=restarts_along_unmeasured_springs(at.run, at.best))


@dataclass(frozen=True)
class OnTheBox:
    """Ends the fit where its end lies on the default box and ``box`` opens it (the fit is
    repeated in the opened box)."""

    box: BoxOpening

    def __call__(self, at: Standing) -> Standing:
        result = at.run.result(at.best)
        return replace(at, ended=result) if self.box.opened(at.run.options, result) else at


class NoiseLevels:
    """Noise levels estimated with the fit (``noise_rounds.estimate_noise``) where
    ``FitOptions.noise`` asks for them: "estimate", or "auto" and the fit does not reach
    the sensors' noise (``StrategySettings.mismatch_rms``) or deferred to the rounds. The
    fit is then of the problem weighted by the estimated levels, and says so."""

    def __call__(self, at: Standing) -> Standing:
        run, options = at.run, at.run.options
        rms = run.ms.residual_rms(at.best.state.evaluation.cost)
        mismatch = at.deferred or rms > options.strategy.mismatch_rms
        if not (options.noise == "estimate" or (options.noise == "auto" and mismatch)):
            return at
        run, state, gn, rounds, settling = estimate_noise(
            run, at.best.state, at.recordings, at.sensor_std
        )
        best = Fitted(state, gn, run.statistics(gn, state))
        return replace(at, run=run, best=best, rounds=rounds, settling=settling)


class ReplayedRest:
    """The last solve, from the replay's rest state (``replayed_rest``), after a converged
    stage; where its end is kept and the levels were estimated, the noise rounds go on from
    it (the levels of the point the fit reports). With rounds to follow, the solve is one:
    it ends once re-weighting gains more (on dev plant 57 of issue 25 it ran 51 of the first
    fit's 101 s to its tolerance, and the levels it was solved at then moved by 2 x)."""

    def __call__(self, at: Standing) -> Standing:
        if not (at.run.stages[-1].converged and replays_rest(at.run)):
            return at
        rounds_follow = 0 < at.rounds < at.run.options.strategy.max_noise_rounds
        run, best = solve_from_replayed_rest(
            at.run, at.best, at.recordings, at.rounds > 0, at.sensor_std if rounds_follow else None
        )
        at = replace(at, run=run, best=best)
        if not (at.rounds and run.options.rest_start == "replay"):
            return at
        run, state, gn, rounds, settling = estimate_noise(
            run, best.state, at.recordings, at.sensor_std, at.rounds + 1, best.solver
        )
        if state is not best.state:
            best = Fitted(state, gn, run.statistics(gn, state), best.held)
        return replace(at, run=run, best=best, rounds=rounds, settling=settling)


@dataclass(frozen=True)
class OpenedBox:
    """A fit that ends on the default box after its noise rounds goes on from its end, at
    its noise levels, in the box ``box`` opens, until it ends off the box or nothing is left
    to open: the same problem with wider bounds (friction in linear scale where it opens to
    zero), the rounds continued from the levels reached, then the last solve from the
    replay's rest state if it has not run. Repeating the whole fit in the opened box ran its
    rounds again from the sensors' weights: on the slow class of issue 25 (friction 3.4 x,
    the box opened twice) three fits of hframe-8 in 659 s, each with its rounds and a solve
    from rest of 14-89 s (docs/studies/)."""

    box: BoxOpening

    def __call__(self, at: Standing) -> Standing:
        while True:
            result = at.run.result(at.best)
            options = self.box.opened(at.run.options, result)
            if options is None or at.run.against_the_wall(at.best.state.theta):
                return at
            at = ReplayedRest()(_continued_in(options, at, result))


def _continued_in(options: FitOptions, at: Standing, ended: FitResult) -> Standing:
    """Where the fit stands after going on from ``ended`` (``at``'s end) in the box of
    ``options``: the rounds continued at its levels (a solve at the sensors' weights if they
    were not estimated), a stage recording the box it opened first."""
    problem = build_problem(at.recordings, at.run.problem.initial, options)
    ms = MultipleShooting(problem, transcription=options.transcription_options)
    run = replace(at.run, problem=problem, ms=ms, options=options)
    state = replace(
        at.best.state,
        theta=problem.theta_of(ended.parameters),
        active=np.ones(len(problem.free), dtype=bool),
    )
    run.stages.append(opened_box_report(ended, at.run.options, options))
    if not at.rounds:
        state, gn = warm_solve(run, state, OPENED_BOX_STAGE)
        return replace(at, run=run, best=Fitted(state, gn, run.statistics(gn, state)))
    run, state, gn, rounds, settling = estimate_noise(run, state, at.recordings, at.sensor_std)
    best = Fitted(state, gn, run.statistics(gn, state))
    earlier = at.earlier_rounds + at.rounds
    return replace(at, run=run, best=best, rounds=rounds, settling=settling, earlier_rounds=earlier)


def _finished(at: Standing) -> FitResult:
    """The result of the fit's end: its noise report, the misfit judgement, the held
    parameters' uncertainty and the wall time."""
    run, best = at.run, at.best
    best.solver.evaluations = run.counter["evaluations"]
    rounds = at.earlier_rounds + at.rounds
    result = run.result(best)
    result = result.with_diagnostics(
        noise=noise_report(
            run.problem, at.sensor_std, result.diagnostics.channel_rms, rounds, at.settling
        )
    )
    result = _misfit_judged(result, run.ms, best.state, at.sensor_std, estimated=bool(rounds))
    result = include_held_uncertainty(run.problem, at.recordings, best.state, result)
    return replace(result, wall_time_s=time.perf_counter() - run.started)


def _started_run(
    recordings: list[Recording], initial: ParameterSet, options: FitOptions, regress: bool = True
) -> FitRun:
    """The ``FitRun`` of a fit of ``recordings`` from ``initial`` with ``options``: the
    problem, its transcription, the nodes from the measurements and, with ``regress`` unless
    ``options.first_stage`` is off, the equation-error regression (once for every attempt
    and for the known points, ``FitResult.equation_error``)."""
    started = time.perf_counter()
    options = options.for_model(initial.variant)
    problem = build_problem(recordings, initial, options)
    ms = MultipleShooting(problem, transcription=options.transcription_options)
    progress = progress_sink(options)
    nodes, velocity = ms.initial_nodes(problem.p_initial)
    regression = None
    if options.first_stage and regress:
        theta = equation_error_start(
            problem, ms.measured_positions, ms.measured_usable, threads=ms.threads
        )
        regression = (theta, time.perf_counter() - started)
    return FitRun(problem, options, ms, nodes, velocity, regression, progress, started)


def _misfit_judged(result: FitResult, ms, state, sensor_std: np.ndarray, estimated: bool):
    """``result`` with its residual rms in units of the sensors' noise (``sensor_std`` [SI]:
    the user's ``channel_std`` or the rig's specification, never a level estimated from the
    residuals) in ``diagnostics.residual_rms_sensor_std``, failed as a poor fit if that
    exceeds the misfit limit: ``FitOptions.max_misfit`` if given, else ``DEFAULT_MAX_MISFIT``
    for a fit weighted by the sensors' noise, and no limit for one that estimated its noise
    levels (model mismatch: stated with its evidence in the report, and judged against the
    points the fit knows instead)."""
    used = ms.weight > 0
    residual = unweighted_residuals(ms, state.evaluation) / sensor_std
    misfit = float(np.sqrt(np.mean(residual[used] ** 2))) if used.any() else math.nan
    result = result.with_diagnostics(residual_rms_sensor_std=misfit)
    options = result.options
    limit = options.max_misfit
    if limit is None and not estimated:
        limit = DEFAULT_MAX_MISFIT
    if not result.success or limit is None or not misfit > limit:
        return result
    given = "FitOptions.max_misfit / --max-misfit" if options.max_misfit else "the default"
    return replace(
        result,
        success=False,
        message=f"converged to a poor fit: residual rms {misfit:.3g} x the sensors' noise "
        f"(limit {limit:g}, {given}); a local optimum far from the data, or a model that "
        "cannot follow it: try a start closer to the plant",
    )


def _best_attempt(run: FitRun, prepasses: list[bool]) -> Fitted:
    """The first of the attempts (one for each of ``prepasses``, in order) whose last stage
    converged or deferred to the noise rounds, else the one of lowest cost."""
    best = None
    for prepass in prepasses:
        outcome = _attempt(run, prepass)
        if run.stages[-1].converged or run.stages[-1].name == DEFERRED_STAGE:
            return outcome
        if best is None or outcome.state.evaluation.cost < best.state.evaluation.cost:
            best = outcome
    return best


def _attempt(run: FitRun, prepass: bool) -> Fitted:
    """The equation-error start, the output-error stages and the identifiability holds, from
    the run's start (with the state-estimation pre-pass if ``prepass``)."""
    theta = _start(run, prepass)
    active = np.ones(len(run.problem.free), dtype=bool)
    state, gn = solve(run, theta, active, prepass, defer_on_mismatch=True)
    fitted = Fitted(state, gn, run.statistics(gn, state))
    mismatch_rms = run.options.strategy.mismatch_rms
    if run.options.noise != "sensor" and run.ms.residual_rms(state.evaluation.cost) > mismatch_rms:
        # Model mismatch: identifiability is decided after the noise levels are estimated.
        return fitted

    def resolve(theta, active):
        # Holding a parameter that had wandered along a sloppy valley moves the optimum of
        # the others (its collinear partners compensate): solve again from the measured
        # nodes, with the other parameters where they were.
        return solve(run, theta, active, prepass)

    return hold_unidentified(run, fitted, resolve)


def _start(run: FitRun, prepass: bool) -> np.ndarray:
    """The log-parameters the output-error stages start from: the given start (theta 0), or
    the run's equation-error regression if it fits the data better (reported as a stage)."""
    start = time.perf_counter()
    ms, nodes, velocity = run.ms, run.nodes, run.velocity
    n_free = len(run.problem.free)
    theta = np.zeros(n_free)
    if run.regression is None:
        return theta
    regressed, seconds = run.regression
    # Keep the regression only if it fits the data better than the given start does
    # (both judged by the output error of independent shooting windows: one evaluation
    # each). It is biased and can be poor where a coordinate is not measured.
    if prepass:
        # Judged after estimating the node states at each: from the measured nodes (an
        # unmeasured coordinate on the rigid motion) the truth itself can lose to a
        # poorer regression (docs/fitting.md, "One-axis").
        active0 = np.ones(n_free, dtype=bool)
        costs = [run.estimate_states(ms, nodes, th, active0, [])[1] for th in (theta, regressed)]
    else:
        probe = ms.subset(np.arange(ms.n_windows), linked=False)
        smoothing = run.problem.smoothing
        costs = [
            probe.evaluate(nodes, th, smoothing, velocity_hint=velocity, derivatives=False).cost
            for th in (theta, regressed)
        ]
        run.add_evaluations(2)
    used = bool(np.isfinite(costs[1]) and costs[1] < costs[0])
    run.stages.append(equation_error_report(seconds + time.perf_counter() - start, used))
    return regressed if used else theta
