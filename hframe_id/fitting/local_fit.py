"""One fit inside one box of parameter bounds: the stages from a start to an optimum.

Stages (``docs/fitting.md`` has the measurements behind each choice):

1. equation error: the models are linear in their parameters once multiplied by the mass
   matrix, so a regression on differentiated measurements gives a start in milliseconds
   (kept only if it fits the data better than the given start);
2. multiple shooting on the windows where something moves (the dynamics; the stiff stretches
   at rest cost most and tell least): exact continuity by condensed Gauss-Newton, or, if that
   fails from a poor start, first continuity as a penalty, then exact;
3. every window, every sample with the substeps the stiffest window needs (the discretization
   of a simulation), nodes at rest filled by simulating the fitted model;
4. statistics at the optimum; free parameters whose relative standard error exceeds the
   identifiability threshold are held at their initial value and stages 2-3 re-run; for
   each held parameter :mod:`hframe_id.fitting.design_advice` names the standard
   experiments that would identify it.

A model with a coordinate no output measures (one-axis: the idler) first tries all this with
the node states estimated at the parameters held (a state-estimation pre-pass), and if that
does not converge, again from the measured nodes.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import casadi as ca
import numpy as np

from hframe_id.fitting.equation_error import equation_error_start
from hframe_id.fitting.estimates import fit_result
from hframe_id.fitting.held_uncertainty import include_held_uncertainty
from hframe_id.fitting.noise_rounds import MISMATCH_RMS, estimate_noise, noise_report
from hframe_id.fitting.options import FitOptions
from hframe_id.fitting.problem import FitProblem, build_problem
from hframe_id.fitting.progress import labelled, progress_sink
from hframe_id.fitting.result import FitResult
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.fitting.solver import GaussNewton, SolverState, StageReport
from hframe_id.fitting.solvers import solver_named
from hframe_id.fitting.stages import (
    INTERMEDIATE_DEFECT_TOL,
    INTERMEDIATE_STEP_TOL,
    equation_error_report,
    estimate_states,
    exact_stage,
    penalty_stage,
)
from hframe_id.fitting.statistics import Statistics, compute_statistics
from hframe_id.parameters import ParameterSet
from hframe_id.recordings.recording import Recording

#: Residual rms (noise std) above which an unconverged fit is not worth holding parameters.
MISFIT = 1.5


#: Misfit limit of a fit weighted by the sensors' noise (residual rms in sensor std) when
#: ``FitOptions.max_misfit`` is not given: far above a correct fit on sim-rig data (1.0-1.3),
#: far below the wrong optima measured on one-axis data (10-45).
DEFAULT_MAX_MISFIT = 5.0


#: Relative standard error above which parameters are held together, not one at a time.
HOPELESS_STD = 1.0


#: Iterations without progress after which the fast path (exact continuity on the moving
#: windows straight from the start) hands over to the penalty fallback (solver.GIVE_UP_*).
FAST_PATH_PATIENCE = 6


#: Restarts along the stiffnesses at an unmeasured coordinate (see
#: ``_restarts_along_unmeasured_springs``): factors, at most this many, and the cost decrease
#: (chi^2 / 2 units: 2 is a likelihood-ratio of e^2) a restart must bring to be kept.
RESTART_FACTORS = (1.18, 1.4)


RESTART_LIMIT = 16


RESTART_MIN_GAIN = 2.0


DEFERRED_STAGE = "all windows: deferred to the noise rounds"


def _scaled(smoothing: tuple[float, float], factor: float) -> tuple[float, float]:
    return (smoothing[0] * factor, smoothing[1] * factor)


def _stats(gn: GaussNewton, state: SolverState, problem: FitProblem, method: str) -> Statistics:
    """The statistics at ``state`` by the ``FitOptions.uncertainty`` ``method``."""
    ev = state.evaluation
    jac, residual, blocks = gn.condensed_jacobian(ev, state.nodes, state.active)
    n_nuisance = gn.ms.n_nuisance
    names = tuple(n for n, a in zip(problem.free_names, state.active, strict=True) if a)
    return compute_statistics(jac, residual, blocks, n_nuisance, names, method)


def fit_in_box(
    recordings: list[Recording],
    initial: ParameterSet,
    options: FitOptions,
    may_widen: bool = False,
) -> FitResult:
    """``fit_recordings`` within the box of ``options`` (its bounds and bound factor). With
    ``may_widen``, a first solve that ends on the default box returns before the noise
    rounds (the box will be opened and the fit repeated: measured on the lubricated plant of
    issue 25, the rounds took 25 of the 27 s of a fit whose six friction terms ended on the
    box after the first solve and stayed there)."""
    start = time.perf_counter()
    options = options.for_model(initial.variant)
    problem = build_problem(recordings, initial, options)
    ms = MultipleShooting(problem, transcription=options.transcription_options)
    progress = progress_sink(options)
    nodes, velocity = ms.initial_nodes(problem.p_initial)
    stages: list[StageReport] = []
    counter = {"evaluations": 0}
    # The equation-error regression (theta, seconds), once for every attempt and for the
    # known points (``FitResult.equation_error``).
    regression = None
    if options.first_stage:
        theta = equation_error_start(
            problem, ms.measured_positions, ms.measured_usable, threads=ms.threads
        )
        regression = (theta, time.perf_counter() - start)
    # One-axis (a coordinate no output measures): first with the node states estimated at
    # the parameters held (converges from the truth on fresh plants, where the path from the
    # measured nodes left it); if that fails, the path from the measured nodes (which fits
    # the shipped pulses from Table 2.3, where the pre-pass path stalled). docs/fitting.md.
    unmeasured = _unmeasured_coordinates(ms) and options.state_prepass
    attempts = [True, False] if unmeasured else [False]
    best = None
    for prepass in attempts:
        outcome = _attempt(
            problem, options, ms, nodes, velocity, stages, counter, progress, prepass, regression
        )
        state, gn, stats, held = outcome
        if stages[-1].converged or stages[-1].name == DEFERRED_STAGE:
            best = outcome
            break
        if best is None or state.evaluation.cost < best[0].evaluation.cost:
            best = outcome
    deferred = stages[-1].name == DEFERRED_STAGE
    if unmeasured and not deferred:
        best = _restarts_along_unmeasured_springs(
            problem, options, ms, nodes, velocity, stages, counter, progress, best
        )
    if may_widen:
        early = fit_result(
            problem, options, ms, best[1], best[0], stages, best[2], best[3], start, regression
        )
        if early.diagnostics.at_default_box:
            return early
    sensor_std = problem.channel_std.copy()
    rounds = 0
    settling = None
    state = best[0]
    mismatch = deferred or ms.residual_rms(state.evaluation.cost) > MISMATCH_RMS
    if options.noise == "estimate" or (options.noise == "auto" and mismatch):
        problem, ms, state, gn, rounds, settling = estimate_noise(
            problem, ms, state, recordings, stages, counter, progress, options
        )
        # The fit is now of the problem weighted by the estimated levels, and says so.
        options = replace(options, channel_std=problem.problem_options.channel_std)
        best = (state, gn, _stats(gn, state, problem, options.uncertainty), {})
    state, gn, stats, held = best
    gn.evaluations = counter["evaluations"]
    result = fit_result(problem, options, ms, gn, state, stages, stats, held, start, regression)
    result = result.with_diagnostics(
        noise=noise_report(problem, sensor_std, result.diagnostics.channel_rms, rounds, settling)
    )
    result = _misfit_judged(result, ms, state, sensor_std, estimated=bool(rounds))
    result = include_held_uncertainty(problem, recordings, state, result)
    result = replace(result, wall_time_s=time.perf_counter() - start)
    return result


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


def _restarts_along_unmeasured_springs(
    problem, options, ms, nodes, velocity, stages, counter, progress, best
):
    """Restarts with each free stiffness of a belt section at an unmeasured pulley moved by
    x/÷ each of ``RESTART_FACTORS``; keeps the lowest converged cost, repeated while it
    improves (at most ``RESTART_LIMIT`` solves). Also run when the fit has not converged: a
    converged restart replaces it.

    The unmeasured idler's mode (set by k2 + k3 against J_2) makes the output error
    multimodal along those stiffnesses, as a sinusoid's frequency is; each restart is one
    ``_solve`` from the fit's end point with one stiffness moved. docs/fitting.md, "One-axis",
    has the cost profile and what the restarts change. Returns (state, solver, statistics,
    held) like ``_attempt``.
    """
    state, gn, stats, held = best
    springs = _springs_at_unmeasured_coordinates(problem, ms)
    start = time.perf_counter()
    tried = iterations = 0
    improved = True
    while improved and tried < RESTART_LIMIT:
        improved = False
        for index in springs:
            for factor in (f**sign for f in RESTART_FACTORS for sign in (1, -1)):
                if not state.active[index] or tried >= RESTART_LIMIT:
                    continue
                theta = state.theta.copy()
                theta[index] = np.clip(
                    theta[index] + math.log(factor),
                    problem.theta_lower[index],
                    problem.theta_upper[index],
                )
                trial_stages: list[StageReport] = []
                label = f"restart {tried + 1}, {problem.free_names[index]} x{factor:.3g}"
                trial_state, trial_gn = _solve(
                    problem,
                    options,
                    ms,
                    nodes,
                    velocity,
                    theta,
                    state.active.copy(),
                    trial_stages,
                    counter,
                    labelled(progress, label),
                    prepass=True,
                )
                tried += 1
                iterations += sum(st.iterations for st in trial_stages)
                gain = state.evaluation.cost - trial_state.evaluation.cost
                if trial_stages[-1].converged and gain > RESTART_MIN_GAIN:
                    state, gn, final = trial_state, trial_gn, trial_stages[-1]
                    improved = True
    if state is best[0]:
        final = stages[-1]
    else:
        stats = _stats(gn, state, problem, options.uncertainty)
    stages.append(
        replace(
            final,
            name=f"restarts along {', '.join(problem.free_names[i] for i in springs)}",
            iterations=iterations,
            wall_time_s=time.perf_counter() - start,
            message=f"{final.message}; {tried} restarts "
            f"(x/÷{', '.join(f'{f:g}' for f in RESTART_FACTORS)}), "
            f"best cost {state.evaluation.cost:.6g}",
        )
    )
    return state, gn, stats, held


def _springs_at_unmeasured_coordinates(problem: FitProblem, ms: MultipleShooting) -> list[int]:
    """Free parameters (indices into ``problem.free``) that enter the generalised force on
    a coordinate no output measures through the potential energy (one-axis: k2, k3)."""
    model = problem.model
    x = ca.SX.sym("x", model.n_states)
    p = ca.SX.sym("p", len(model.parameters))
    _, potential = model.energy(x, p)
    unmeasured = np.flatnonzero(~_measured_coordinates(ms))
    force = ca.gradient(potential, x)[unmeasured.tolist()]
    coupled = {j for j in range(p.shape[0]) if ca.depends_on(force, p[j])}
    return [f for f, i in enumerate(problem.free) if i in coupled]


def _attempt(problem, options, ms, nodes, velocity, stages, counter, progress, prepass, regression):
    """Equation-error start (``regression``: its theta and the seconds it took, or None),
    output-error stages and the identifiability holds, from the given start (with the
    state-estimation pre-pass if ``prepass``), with the fit's ``options``."""
    start = time.perf_counter()
    n_free = len(problem.free)
    theta = np.zeros(n_free)
    smoothing = problem.smoothing
    if regression is not None:
        regressed, seconds = regression
        # Keep the regression only if it fits the data better than the given start does
        # (both judged by the output error of independent shooting windows: one evaluation
        # each). It is biased and can be poor where a coordinate is not measured.
        if prepass:
            # Judged after estimating the node states at each: from the measured nodes (an
            # unmeasured coordinate on the rigid motion) the truth itself can lose to a
            # poorer regression (docs/fitting.md, "One-axis").
            active0 = np.ones(n_free, dtype=bool)
            trials = [
                estimate_states(ms, nodes, velocity, th, active0, [], progress)
                for th in (theta, regressed)
            ]
            costs = [merit for _, merit in trials]
        else:
            probe = ms.subset(np.arange(ms.n_windows), linked=False)
            costs = [
                probe.evaluate(nodes, th, smoothing, velocity_hint=velocity, derivatives=False).cost
                for th in (theta, regressed)
            ]
        counter["evaluations"] += 2
        used = bool(np.isfinite(costs[1]) and costs[1] < costs[0])
        if used:
            theta = regressed
        stages.append(equation_error_report(seconds + time.perf_counter() - start, used))
    active = np.ones(n_free, dtype=bool)
    state, gn = _solve(
        problem,
        options,
        ms,
        nodes,
        velocity,
        theta,
        active,
        stages,
        counter,
        progress,
        prepass,
        True,
    )
    stats = _stats(gn, state, problem, options.uncertainty)
    if options.noise != "sensor" and ms.residual_rms(state.evaluation.cost) > MISMATCH_RMS:
        # Model mismatch: identifiability is decided after the noise levels are estimated.
        return state, gn, stats, {}

    def resolve(theta, active):
        # Holding a parameter that had wandered along a sloppy valley moves the optimum of
        # the others (its collinear partners compensate): solve again from the measured
        # nodes, with the other parameters where they were.
        return _solve(
            problem, options, ms, nodes, velocity, theta, active, stages, counter, progress, prepass
        )

    return _hold_unidentified(problem, options, ms, state, gn, stats, stages, resolve)


def _hold_unidentified(problem, options, ms, state, gn, stats, stages, resolve):
    """Holds free parameters whose relative standard error exceeds the identifiability
    threshold at their initial value, the worst first, and solves again with
    ``resolve(theta, active) -> (state, solver)``, until every parameter left is identified.
    Returns (state, solver, statistics, held)."""
    n_free = len(problem.free)
    held: dict[str, tuple[float, float, float]] = {}
    for _ in range(n_free):
        # Also when the stage did not converge, if the fit is at the noise level: a sloppy
        # direction (a parameter the data hardly determine) is the usual reason, and holding
        # it lets the rest converge. Far from a fit, error estimates mean nothing: fail.
        if not stages[-1].converged and ms.residual_rms(state.evaluation.cost) > MISFIT:
            break
        active_idx = np.flatnonzero(state.active)
        # A parameter with a prior (``FitProblem.prior_weight``) is never held: the prior
        # determines what the data do not.
        judged = np.where(problem.prior_weight[active_idx] > 0, 0.0, stats.relative_std)
        worst = int(np.argmax(judged))
        if judged[worst] <= options.identifiability_threshold:
            break
        # The worst first (fixing one of a collinear pair can identify the other), together
        # with every parameter the data plainly do not determine (relative std > 100 %).
        hold = {worst} | set(np.flatnonzero(judged > HOPELESS_STD).tolist())
        active = state.active.copy()
        theta = state.theta.copy()
        for k in sorted(hold):
            index = int(active_idx[k])
            held[problem.free_names[index]] = (
                float(stats.relative_std[k]),
                float(stats.relative_std_gn[k]),
                float(stats.collinearity[k]),
            )
            active[index] = False
            theta[index] = 0.0
        if not active.any():
            break
        state, gn = resolve(theta, active)
        stats = _stats(gn, state, problem, options.uncertainty)
    return state, gn, stats, held


def _moving_window_stages(
    problem,
    options,
    ms,
    moving,
    nodes,
    velocity,
    theta,
    active,
    stages,
    counter,
    progress,
    prepass,
    defer_on_mismatch,
):
    """The stages on the ``moving`` windows (exact continuity from the start, or the penalty
    fallback), then every node filled by simulating from them. Returns (nodes, theta,
    mismatch, moving_rms): whether the fit defers to the noise rounds (see ``_solve``), and
    the moving windows' residual rms [noise std]."""
    smoothing = problem.smoothing
    schedule = options.smoothing_schedule
    nodes = nodes.copy()
    sub = ms.subset(moving)
    gn_sub = GaussNewton(sub, progress)
    for use_penalty in (False, True):
        # Fast path: exact continuity straight from the start. If that fails (a poor
        # start), the fallback first relaxes continuity into a penalty.
        sub_state = SolverState(
            nodes[moving].copy(),
            theta.copy(),
            active.copy(),
            velocity_hint=velocity[moving],
        )
        if use_penalty:
            stages.append(
                penalty_stage(
                    gn_sub,
                    sub_state,
                    _scaled(smoothing, schedule[0]),
                    options,
                    "moving windows",
                )
            )
        for factor in schedule:
            stages.append(
                gn_sub.run(
                    sub_state,
                    "moving windows",
                    _scaled(smoothing, factor),
                    options.max_iterations,
                    INTERMEDIATE_STEP_TOL,
                    INTERMEDIATE_DEFECT_TOL,
                    radius=0.5,
                    give_up=None if use_penalty else FAST_PATH_PATIENCE,
                )
            )
        if stages[-1].converged:
            break
    counter["evaluations"] += gn_sub.evaluations
    theta = sub_state.theta
    moving_rms = sub.residual_rms(sub_state.evaluation.cost)
    # With a coordinate no output measures (``prepass``: one-axis), only a converged
    # stage is evidence of mismatch: one that stalled far from the data may be the
    # idler's multimodal mode from a poor start (a held idler 10-20 % off), which the
    # all-window stages and the restarts along its springs, skipped when deferring,
    # resolve (held study: coverage 0.793 -> 0.894). Without one (hframe-8), a stalled
    # stage still counts: the rule was tried there on three realistic plants only,
    # which it did not improve. docs/fitting.md, "Held parameters".
    mismatch = (
        defer_on_mismatch
        and options.noise != "sensor"
        and (stages[-1].converged or not prepass)
        and moving_rms > MISMATCH_RMS
    )
    known = np.zeros(ms.n_windows, dtype=bool)
    known[moving] = True
    # The first moving window of each stretch starts at rest (it is the margin before
    # the motion): simulate through it from the rest before, so that the one junction
    # left (to the next window) lies in motion, where closing it is a linear matter.
    starts = moving[np.r_[True, np.diff(moving) > 1]]
    known[starts] = False
    nodes[moving] = sub_state.nodes
    nodes = ms.fill_nodes(nodes, known, theta, smoothing)
    return nodes, theta, mismatch, moving_rms


def _solve(
    problem,
    options,
    ms,
    nodes,
    velocity,
    theta,
    active,
    stages,
    counter,
    progress,
    prepass=False,
    defer_on_mismatch=False,
):
    """Output-error stages from ``theta``: moving windows (exact, penalty fallback), then
    every window with uniform substeps. Returns the final solver state and solver.

    With ``defer_on_mismatch`` (the first solve of a fit whose noise levels may be
    estimated), moving windows that end far above the sensors' noise level skip the
    all-window stages, leaving them to the noise rounds (the last stage is then
    ``DEFERRED_STAGE``, not converged). Restarts and holds never defer: their outcome is
    judged by a converged all-window stage."""
    smoothing = problem.smoothing
    theta = theta.copy()
    if prepass:
        nodes, _ = estimate_states(ms, nodes, velocity, theta, active, stages, progress)
    measured = nodes
    nodes = nodes.copy()
    # Stages on the windows where something moves: they carry the dynamics, and leaving out
    # the stiff stretches at rest makes each evaluation several times cheaper.
    moving = ms.moving_windows(velocity, smoothing) if options.first_stage else np.arange(0)
    mismatch, moving_rms = False, math.nan
    if 0 < moving.size < ms.n_windows:
        nodes, theta, mismatch, moving_rms = _moving_window_stages(
            problem,
            options,
            ms,
            moving,
            nodes,
            velocity,
            theta,
            active,
            stages,
            counter,
            progress,
            prepass,
            defer_on_mismatch,
        )
    ms = ms.uniform()
    if prepass and moving.size and not mismatch:
        # The nodes at rest were simulated with the moving-window parameters, which put an
        # unmeasured pulley's stretch wherever those left it: estimate them again with the
        # parameters held (docs/fitting.md, "One-axis", the second pre-pass). Not under
        # mismatch: there the pre-pass (continuity a penalty) follows the data with a
        # discontinuous trajectory, and the noise rounds would estimate the noise from it
        # (realistic one-axis plant 2: defects of 79 sensor std, noise 33 sensor std where
        # continuous trajectories are at 0.2-3 rad) and stall (docs/fitting.md).
        nodes, _ = estimate_states(ms, nodes, velocity, theta, active, stages, progress)
    gn = GaussNewton(ms, progress, freeze_sloppy=True)
    if mismatch:
        # The model does not follow the data at the sensors' noise level: the weights are
        # wrong by orders of magnitude, so the all-window stages are left to the noise
        # rounds (``noise_rounds.estimate_noise``), which start from here.
        state = SolverState(nodes, theta, active.copy(), velocity_hint=velocity)
        state.evaluation = ms.evaluate(nodes, theta, smoothing, velocity_hint=velocity)
        stages.append(
            StageReport(
                name=DEFERRED_STAGE,
                smoothing=smoothing,
                iterations=0,
                converged=False,
                message=f"residual rms {moving_rms:.3g} sensor std on the moving windows: "
                "the model does not follow the data at the sensors' noise level",
                cost=state.evaluation.cost,
                max_defect=float(np.max(np.abs(ms.defects(state.evaluation, nodes)), initial=0)),
                wall_time_s=0.0,
            )
        )
        return state, gn
    # Exact continuity from the nodes so far; if that fails (nodes at rest simulated with
    # parameters that are still off, e.g. an unmeasured pulley's stretch at rest), the same
    # fallback as above from the measured nodes: continuity first as a penalty, then exact.
    # (Unless the solver globalises by itself: ``Solver.penalty_fallback``.)
    fallback = solver_named(options.solver).penalty_fallback
    for use_penalty in (False, True)[: 2 if fallback else 1]:
        start_nodes = measured if use_penalty else nodes
        state = SolverState(start_nodes.copy(), theta.copy(), active.copy(), velocity_hint=velocity)
        if use_penalty:
            stages.append(penalty_stage(gn, state, smoothing, options, "all windows"))
        stages.append(exact_stage(gn, state, "all windows", options.solver_options, radius=0.5))
        if stages[-1].converged:
            break
    counter["evaluations"] += gn.evaluations
    return state, gn


def _measured_coordinates(ms: MultipleShooting) -> np.ndarray:
    """(n_q,) True for the coordinates an output measures, by their position or their rate
    (a tachometer)."""
    seen = np.any(ms.c[:, : ms.nq] != 0, axis=0)
    states = ms.output_states[ms.output_states >= 0]
    seen[states % ms.nq] = True
    return seen


def _unmeasured_coordinates(ms: MultipleShooting) -> bool:
    """Whether some coordinate is measured by no output (one-axis: the idler pulley)."""
    return not bool(np.all(_measured_coordinates(ms)))
