"""The output-error stages of a fit from one start: the moving windows, then every window.

1. multiple shooting on the windows where something moves (they carry the dynamics; the
   stiff stretches at rest cost most and tell least): exact continuity by condensed
   Gauss-Newton straight from the start, or, if that stalls, first continuity as a penalty,
   then exact; the nodes at rest are then filled by simulating the fitted model;
2. every window, every sample with the substeps the stiffest window needs (the
   discretization of a simulation), by the solver ``FitOptions.solver`` names, with the same
   penalty fallback from the measured nodes (unless the solver globalises by itself).

``docs/fitting.md`` has the measurements behind each choice.
"""

from __future__ import annotations

import math

import numpy as np

from hframe_id.fitting.fit_run import FitRun
from hframe_id.fitting.resolution import resolution_interrupt
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.fitting.solver import GaussNewton, SolverState, StageReport
from hframe_id.fitting.solvers import solver_named
from hframe_id.fitting.stages import exact_stage, penalty_stage

DEFERRED_STAGE = "all windows: deferred to the noise rounds"


def _scaled(smoothing: tuple[float, float], factor: float) -> tuple[float, float]:
    return (smoothing[0] * factor, smoothing[1] * factor)


def solve(
    run: FitRun,
    theta: np.ndarray,
    active: np.ndarray,
    prepass: bool = False,
    defer_on_mismatch: bool = False,
) -> tuple[SolverState, GaussNewton]:
    """Output-error stages from the log-parameters ``theta`` (those ``active`` free) and
    the run's measured nodes: moving windows (exact, penalty fallback), then every window
    with uniform substeps. With ``prepass`` (a coordinate no output measures), the node
    states are first estimated at ``theta`` held (``stages.estimate_states``), and again
    before the all-window stage. Returns the final solver state and solver.

    With ``defer_on_mismatch`` (the first solve of a fit whose noise levels may be
    estimated), moving windows that end far above the sensors' noise level skip the
    all-window stages, leaving them to the noise rounds (the last stage is then
    ``DEFERRED_STAGE``, not converged). Restarts and holds never defer: their outcome is
    judged by a converged all-window stage."""
    problem, options, ms, velocity = run.problem, run.options, run.ms, run.velocity
    smoothing = problem.smoothing
    theta = theta.copy()
    nodes = run.nodes
    if prepass:
        nodes, _ = run.estimate_states(ms, nodes, theta, active, run.stages)
    measured = nodes
    nodes = nodes.copy()
    # Stages on the windows where something moves: they carry the dynamics, and leaving out
    # the stiff stretches at rest makes each evaluation several times cheaper.
    moving = ms.moving_windows(velocity, smoothing) if options.first_stage else np.arange(0)
    mismatch, moving_rms = False, math.nan
    if 0 < moving.size < ms.n_windows:
        may_defer = defer_on_mismatch and options.noise != "sensor"
        # Without ``prepass``, the moving windows' outcome under mismatch is only a start
        # for the noise rounds: its fallback may give up as the fast path does.
        nodes, theta, moving_rms = _moving_window_stages(
            run, moving, nodes, theta, active, defers=may_defer and not prepass
        )
        # With a coordinate no output measures (``prepass``: one-axis), only a converged
        # stage is evidence of mismatch: one that stalled far from the data may be the
        # idler's multimodal mode from a poor start (a held idler 10-20 % off), which the
        # all-window stages and the restarts along its springs, skipped when deferring,
        # resolve (held study: coverage 0.793 -> 0.894). Without one (hframe-8), a stalled
        # stage still counts: the rule was tried there on three realistic plants only,
        # which it did not improve. docs/fitting.md, "Held parameters".
        mismatch = (
            may_defer
            and (run.stages[-1].converged or not prepass)
            and moving_rms > options.strategy.mismatch_rms
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
        nodes, _ = run.estimate_states(ms, nodes, theta, active, run.stages)
    gn = run.solver(ms, freeze_sloppy=True)
    if mismatch:
        state = SolverState(nodes, theta, active.copy(), velocity_hint=velocity)
        _defer(run, ms, state, moving_rms)
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
            run.stages.append(penalty_stage(gn, state, smoothing, options, "all windows"))
        run.stages.append(
            exact_stage(
                gn,
                state,
                "all windows",
                options.solver_options,
                radius=0.5,
                interrupt=resolution_interrupt(ms),
            )
        )
        if run.stages[-1].converged:
            break
    run.add_evaluations(gn.evaluations)
    return state, gn


def _moving_window_stages(
    run: FitRun,
    moving: np.ndarray,
    nodes: np.ndarray,
    theta: np.ndarray,
    active: np.ndarray,
    defers: bool = False,
) -> tuple[np.ndarray, np.ndarray, float]:
    """The stages on the ``moving`` windows (indices) from ``nodes`` and ``theta`` (exact
    continuity from the start, or the penalty fallback), then every node filled by
    simulating from them. Returns (nodes, theta, moving_rms): the moving windows' residual
    rms [noise std].

    The fast path gives up once it stops making progress far from the noise level
    (``StrategySettings.fast_path_patience``), handing over to the fallback. The fallback's
    exact stage gives up by the same rule where the solve ``defers`` to the noise rounds a
    result far above the sensors' noise: there it is only the rounds' start, and at weights
    wrong by orders of magnitude (the sensors' std under model error) a crawl optimises
    another criterion than theirs (the seven realistic records' current-limited fit: 150
    iterations, 24 s of 138 s, cost 6.5e9 -> 2.8e9 in sensor units)."""
    problem, options, ms = run.problem, run.options, run.ms
    smoothing = problem.smoothing
    schedule = options.smoothing_schedule
    nodes = nodes.copy()
    sub = ms.subset(moving)
    gn_sub = run.solver(sub)
    for use_penalty in (False, True):
        # Fast path: exact continuity straight from the start. If that fails (a poor
        # start), the fallback first relaxes continuity into a penalty.
        sub_state = SolverState(
            nodes[moving].copy(),
            theta.copy(),
            active.copy(),
            velocity_hint=run.velocity[moving],
        )
        if use_penalty:
            run.stages.append(
                penalty_stage(
                    gn_sub,
                    sub_state,
                    _scaled(smoothing, schedule[0]),
                    options,
                    "moving windows",
                )
            )
        for factor in schedule:
            run.stages.append(
                gn_sub.run(
                    sub_state,
                    "moving windows",
                    _scaled(smoothing, factor),
                    options.max_iterations,
                    options.strategy.intermediate_step_tol,
                    options.strategy.intermediate_defect_tol,
                    radius=0.5,
                    give_up=(
                        options.strategy.fast_path_patience if defers or not use_penalty else None
                    ),
                )
            )
        if run.stages[-1].converged:
            break
    run.add_evaluations(gn_sub.evaluations)
    theta = sub_state.theta
    moving_rms = sub.residual_rms(sub_state.evaluation.cost)
    known = np.zeros(ms.n_windows, dtype=bool)
    known[moving] = True
    # The first moving window of each stretch starts at rest (it is the margin before
    # the motion): simulate through it from the rest before, so that the one junction
    # left (to the next window) lies in motion, where closing it is a linear matter.
    starts = moving[np.r_[True, np.diff(moving) > 1]]
    known[starts] = False
    nodes[moving] = sub_state.nodes
    nodes = ms.fill_nodes(nodes, known, theta, smoothing)
    return nodes, theta, moving_rms


def _defer(run: FitRun, ms: MultipleShooting, state: SolverState, moving_rms: float) -> None:
    """Evaluate ``state`` on every window of ``ms`` (uniform substeps) and report the
    ``DEFERRED_STAGE``: the model does not follow the data at the sensors' noise level
    (``moving_rms`` [noise std] on the moving windows), so the weights are wrong by orders
    of magnitude and the all-window stages are left to the noise rounds
    (``noise_rounds.estimate_noise``), which start from ``state``."""
    smoothing = run.problem.smoothing
    state.evaluation = ms.evaluate(state.nodes, state.theta, smoothing, velocity_hint=run.velocity)
    run.add_evaluations(1)
    run.stages.append(
        StageReport(
            name=DEFERRED_STAGE,
            smoothing=smoothing,
            iterations=0,
            converged=False,
            message=f"residual rms {moving_rms:.3g} sensor std on the moving windows: "
            "the model does not follow the data at the sensors' noise level",
            cost=state.evaluation.cost,
            max_defect=float(np.max(np.abs(ms.defects(state.evaluation, state.nodes)), initial=0)),
            wall_time_s=0.0,
        )
    )
