"""One fit inside one box of parameter bounds: the stages from a start to an optimum.

The strategy, in the order :func:`fit_in_box` runs it (``docs/fitting.md`` has the
measurements behind each choice); each stage is a function of the run's shared state
(:class:`hframe_id.fitting.fit_run.FitRun`):

1. equation error: the models are linear in their parameters once multiplied by the mass
   matrix, so a regression on differentiated measurements gives a start in milliseconds
   (kept only if it fits the data better than the given start; :func:`_start`);
2. the output-error stages (:func:`hframe_id.fitting.output_error.solve`): multiple
   shooting on the windows where something moves, then on every window by the named solver;
3. statistics at the optimum; free parameters whose relative standard error exceeds the
   identifiability threshold are held at their initial value and stage 2 re-run
   (:func:`hframe_id.fitting.holds.hold_unidentified`); for each held parameter
   :mod:`hframe_id.fitting.design_advice` names the standard experiments that would
   identify it;
4. with a coordinate no output measures (one-axis: the idler), restarts along the springs
   that hold it (:func:`hframe_id.fitting.unmeasured.restarts_along_unmeasured_springs`);
5. noise levels estimated with the fit where the model cannot follow the data at the
   sensors' level (:func:`hframe_id.fitting.noise_rounds.estimate_noise`);
6. a last solve with each record at rest started as ``validate`` replays it
   (:func:`hframe_id.fitting.replayed_rest.solve_from_replayed_rest`);
7. the misfit judgement (:func:`_misfit_judged`).

A model with a coordinate no output measures first tries stages 1-3 with the node states
estimated at the parameters held (a state-estimation pre-pass), and if that does not
converge, again from the measured nodes.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from hframe_id.fitting.equation_error import equation_error_start
from hframe_id.fitting.fit_run import FitRun, Fitted
from hframe_id.fitting.held_uncertainty import include_held_uncertainty
from hframe_id.fitting.holds import hold_unidentified
from hframe_id.fitting.noise_rounds import estimate_noise, noise_report
from hframe_id.fitting.options import FitOptions
from hframe_id.fitting.output_error import DEFERRED_STAGE, solve
from hframe_id.fitting.problem import build_problem
from hframe_id.fitting.progress import progress_sink
from hframe_id.fitting.replayed_rest import replays_rest, solve_from_replayed_rest
from hframe_id.fitting.result import FitResult
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.fitting.stages import equation_error_report, estimate_states
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
    may_widen: bool = False,
    screened: bool = False,
) -> FitResult:
    """``fit_recordings`` within the box of ``options`` (its bounds and bound factor). With
    ``may_widen``, a first solve that ends on the default box returns before the noise
    rounds (the box will be opened and the fit repeated: measured on the lubricated plant of
    issue 25, the rounds took 25 of the 27 s of a fit whose six friction terms ended on the
    box after the first solve and stayed there). ``screened``: ``initial`` is the start
    screen's choice (``start_screen``), which judged the equation-error estimate already, by
    the criterion the fit is judged by: the stages begin from ``initial`` as it is."""
    run = _started_run(recordings, initial, options, regress=not screened)
    options = run.options
    # One-axis (a coordinate no output measures): first with the node states estimated at
    # the parameters held (converges from the truth on fresh plants, where the path from the
    # measured nodes left it); if that fails, the path from the measured nodes (which fits
    # the shipped pulses from Table 2.3, where the pre-pass path stalled). docs/fitting.md.
    unmeasured = unmeasured_coordinates(run.ms) and options.state_prepass
    best = _best_attempt(run, [True, False] if unmeasured else [False])
    deferred = run.stages[-1].name == DEFERRED_STAGE
    if unmeasured and not deferred:
        best = restarts_along_unmeasured_springs(run, best)
    if may_widen:
        early = run.result(best)
        if early.diagnostics.at_default_box:
            return early
    sensor_std = run.problem.channel_std.copy()
    rounds = 0
    settling = None
    mismatch = (
        deferred or run.ms.residual_rms(best.state.evaluation.cost) > options.strategy.mismatch_rms
    )
    if options.noise == "estimate" or (options.noise == "auto" and mismatch):
        # The fit is now of the problem weighted by the estimated levels, and says so.
        run, state, gn, rounds, settling = estimate_noise(run, best.state, recordings, sensor_std)
        best = Fitted(state, gn, run.statistics(gn, state))
    if run.stages[-1].converged and replays_rest(run):
        run, best = solve_from_replayed_rest(run, best, recordings)
        if rounds and run.options.rest_start == "replay":
            # Its end kept: the levels of the point the fit reports, the rounds from rest.
            run, state, gn, rounds, settling = estimate_noise(
                run, best.state, recordings, sensor_std, rounds + 1, best.solver
            )
            if state is not best.state:
                best = Fitted(state, gn, run.statistics(gn, state), best.held)
    best.solver.evaluations = run.counter["evaluations"]
    result = run.result(best)
    result = result.with_diagnostics(
        noise=noise_report(
            run.problem, sensor_std, result.diagnostics.channel_rms, rounds, settling
        )
    )
    result = _misfit_judged(result, run.ms, best.state, sensor_std, estimated=bool(rounds))
    result = include_held_uncertainty(run.problem, recordings, best.state, result)
    result = replace(result, wall_time_s=time.perf_counter() - run.started)
    return result


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
    scale = ms.problem.channel_std / sensor_std
    residual = state.evaluation.residual * scale
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
        trials = [
            estimate_states(run.solver(ms), nodes, velocity, th, active0, [], run.options.strategy)
            for th in (theta, regressed)
        ]
        costs = [merit for _, merit in trials]
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
