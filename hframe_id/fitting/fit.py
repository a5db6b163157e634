"""``fit_recordings``: data + model + free parameters -> estimates with honest uncertainty.

The chain (PyBOP-style plain objects): recordings -> :class:`FitProblem` (checked) ->
:class:`MultipleShooting` (transcription) -> :class:`GaussNewton` (solver, stages) ->
:mod:`statistics` (covariance, identifiability) -> :class:`FitResult`.

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
import sys
import time
from dataclasses import dataclass, field, replace
from typing import Any

import casadi as ca
import numpy as np

from hframe_id.fitting.consider import consider_covariance
from hframe_id.fitting.equation_error import equation_error_start
from hframe_id.fitting.known_points import Criterion, known_points, reference_sets
from hframe_id.fitting.multistart import judged, seeded_starts
from hframe_id.fitting.multistart import statement as multistart_statement
from hframe_id.fitting.nlp import NlpSettings, solve_nlp
from hframe_id.fitting.open_ended import LIKELIHOOD_RATIO_95, open_ends
from hframe_id.fitting.options import (
    HELD_PRIOR_RELATIVE_STD,
    FitOptions,
    FitProgress,
)
from hframe_id.fitting.problem import FitProblem, build_problem, consider_priors
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.fitting.solver import GaussNewton, SolverState, StageReport
from hframe_id.fitting.statistics import Statistics, compute_statistics
from hframe_id.parameters import ParameterSet
from hframe_id.recordings.recording import Recording

#: Fallback stage on the moving windows when exact continuity from the equation-error start
#: fails: continuity as a penalty (defects in noise units, this weight), a monotone
#: trust-region method that stops once an iteration gains less than ``PENALTY_COST_RTOL``;
#: it takes a poor start into the basin of the exact (condensed) Gauss-Newton iteration.
PENALTY_WEIGHT = 1.0
PENALTY_COST_RTOL = 1e-3
#: Tolerances of the intermediate stages (the last stage uses the options' step_tol):
#: they only need to bring the iterate into the next stage's basin.
INTERMEDIATE_STEP_TOL = 1e-4
#: Residual rms (noise std) above which an unconverged fit is not worth holding parameters.
MISFIT = 1.5
#: Misfit limit of a fit weighted by the sensors' noise (residual rms in sensor std) when
#: ``FitOptions.max_misfit`` is not given: far above a correct fit on sim-rig data (1.0-1.3),
#: far below the wrong optima measured on one-axis data (10-45).
DEFAULT_MAX_MISFIT = 5.0
#: Relative standard error above which parameters are held together, not one at a time.
HOPELESS_STD = 1.0
INTERMEDIATE_DEFECT_TOL = 1.0
#: Iterations without progress after which the fast path (exact continuity on the moving
#: windows straight from the start) hands over to the penalty fallback (solver.GIVE_UP_*).
FAST_PATH_PATIENCE = 6
#: Restarts along the stiffnesses at an unmeasured coordinate (see
#: ``_restarts_along_unmeasured_springs``): factors, at most this many, and the cost decrease
#: (chi^2 / 2 units: 2 is a likelihood-ratio of e^2) a restart must bring to be kept.
RESTART_FACTORS = (1.18, 1.4)
RESTART_LIMIT = 16
RESTART_MIN_GAIN = 2.0
#: A free parameter closer to a bound than this many of its (relative) standard errors is
#: "at the bound": the bound, not the data, fixes it. Exactly on the bound is not required:
#: under mismatch a parameter running into its bound stopped 2e-4 (relative) short of it
#: when the stage ended on its cost criterion, and was reported converged while a fit with
#: the same parameter 1e-9 closer was reported at the bound. Such a fit still succeeds when
#: its solver converged (issue 9: a failure is a solver that did not converge): the box is
#: part of the problem, and the parameters it stopped are named in the message, the report
#: and the parameter file (``at_bound``), their intervals ending at the bound.
AT_BOUND_STD = 0.1
#: Noise estimation (``FitOptions.noise``): a sensor-weighted fit whose residual rms exceeds
#: this many sensor std does not fit at the noise level (matched sim-rig fits end at
#: 1.0-1.3); rounds of re-weighting at most, and the relative change of every channel's std
#: (in log) below which the noise levels count as a fixed point.
MISMATCH_RMS = 3.0
DEFERRED_STAGE = "all windows: deferred to the noise rounds"
REJECTED_ROUND_STAGE = "noise rounds: the stalled last round rejected"
#: Warm-started noise rounds also stop once an iteration lowers the cost by less than this
#: (relative): at their costs (~N / 2 ~ 1e4, N valid samples) that is ~0.01 in chi^2 / 2
#: units, 1 % of the statistical resolution (1 unit). Without it the monotone trust region
#: can crawl under model mismatch (the l1 merit is not smooth where defects change sign;
#: docs/fitting.md, "Model mismatch").
WARM_COST_RTOL = 1e-6
#: The iteration settles slowly where a channel's level first overshoots: two realistic
#: steps fitted with six parameters free (tests/fitting/test_fit_mismatch.py) moved phi1's
#: std 0.0062, 0.0039, 0.0024, 0.0018, 0.0016, 0.0015 rad and settled in round 7 (measured
#: with casadi 3.8.2 and numpy 2.4.6; with the packages of 2026-11-24 it settled within 5).
MAX_NOISE_ROUNDS = 10
NOISE_RTOL = 0.05
#: Iterations of the state-estimation pre-pass (nodes only, parameters held), and the
#: relative decrease of its merit per iteration below which it stops earlier.
PREPASS_ITERATIONS = 30
PREPASS_COST_RTOL = 1e-4
#: Times a fit that ends on its default box (``FitOptions.bound_factor``) is repeated with
#: the box opened (factor squared: 10, 100, 1e4 by default; friction to zero); still on it
#: after that, the fit fails saying so. Four decades either side of Table 4.2 hold the
#: envelope of issue 25 (masses and stiffness within 0.4-2.5 x; friction, which spans
#: 0.01-10 x and zero, reaches zero after the first opening).
BOX_WIDENINGS = 2


@dataclass(frozen=True)
class ParameterEstimate:
    """One parameter of a fit (SI units).

    ``std_error`` and ``ci95`` come from the covariance chosen in the options (robust to
    correlated residuals by default); the interval is symmetric in log(p), so it is
    [p / f, p * f] with f = exp(z * relative_std), except for signed parameters (offsets),
    fitted linearly, whose interval is p -/+ z std_error. Fixed parameters have zero error and
    ``free`` False; free parameters the data do not identify are held at their initial
    value, with ``identified`` False and the standard error they had when found out. A free
    parameter the box stopped has ``at_bound`` True, ``identified`` False (the bound, not the
    data, fixes it) and an interval that ends at the bound. After a leave-one-recording-out
    cross-validation, ``jackknife_std`` and ``jackknife_ci95`` are the experiment-level
    jackknife's (``fitting.jackknife``), which hold model error that differs between
    experiments; None without one. ``open_ended`` is ``"above"`` or ``"below"`` for a
    parameter on the widened default box that the data bound on the other side only
    (``fitting.open_ended``): its interval runs to infinity or 0.
    """

    name: str
    unit: str
    initial: float
    estimate: float
    std_error: float
    ci95: tuple[float, float]
    identified: bool
    free: bool
    relative_std: float = 0.0
    relative_std_gn: float = 0.0
    collinearity: float = 1.0
    at_bound: bool = False
    identified_by: tuple[str, ...] = ()
    jackknife_std: float | None = None
    jackknife_ci95: tuple[float, float] | None = None
    open_ended: str = ""

    @property
    def key(self) -> str:
        """``"name [unit]"``, as in parameter files and reports."""
        return f"{self.name} [{self.unit}]"


@dataclass
class FitResult:
    """What a fit produced. ``parameters`` holds every parameter (fitted and fixed)."""

    success: bool
    message: str
    parameters: ParameterSet
    estimates: dict[str, ParameterEstimate]
    cost: float
    iterations: int
    wall_time_s: float
    correlation: np.ndarray
    free_names: tuple[str, ...]
    initial: ParameterSet
    options: FitOptions
    stages: list[StageReport] = field(default_factory=list)
    statistics: Statistics | None = None
    not_identified: tuple[str, ...] = ()
    initial_states: np.ndarray | None = None  # (experiments, n_x) estimated
    experiment_names: tuple[str, ...] = ()
    evaluations: int = 0
    problem: FitProblem | None = field(default=None, repr=False)
    diagnostics: dict[str, Any] = field(default_factory=dict)

    @property
    def variant(self) -> str:
        """The model variant fitted."""
        return self.parameters.variant

    @property
    def has_jackknife(self) -> bool:
        """Whether a cross-validation gave any parameter its jackknife interval."""
        return any(est.jackknife_ci95 for est in self.estimates.values())

    @property
    def prior_names(self) -> tuple[str, ...]:
        """Free parameters estimated with a prior (``FitOptions.consider_method`` "prior")."""
        return self.problem.prior_names if self.problem is not None else ()

    @property
    def residual_rms(self) -> float:
        """Residual rms over the valid samples in units of the noise std the channels were
        weighted by (about 1 for a correct model on sim-rig data; about 1 by construction
        once the noise levels were estimated from the residuals)."""
        return float(self.diagnostics.get("residual_rms_noise_std", math.nan))

    @property
    def residual_rms_sensor(self) -> float:
        """Residual rms over the valid samples in units of the sensors' noise std (the
        user's ``channel_std`` or the rig's specification): the misfit that a level estimated
        from the residuals cannot hide."""
        return float(self.diagnostics.get("residual_rms_sensor_std", math.nan))

    def held_statement(self) -> str | None:
        """What the intervals assume about held parameters (None if nothing is held or
        estimated with a prior): which parameters, at which values, with which prior
        relative std, and how the prior entered."""
        consider = self.diagnostics.get("consider", {})
        prior = consider.get("held_relative_std", {})
        sentences = []
        if self.prior_names:
            weights = dict(zip(self.problem.free_names, self.problem.prior_weight, strict=True))
            listed = ", ".join(
                f"{name} (start {self.initial.values[name]:.4g}, +/-{100 / weights[name]:.0f} %)"
                for name in self.prior_names
            )
            sentences.append(
                f"Estimated with a prior on the initial file's values (maximum a posteriori; "
                f"Gaussian in log p): {listed}. Their intervals, and the others', are the "
                f"posterior's: data and prior together."
            )
        if prior:
            held = ", ".join(
                f"{name} = {self.parameters.values[name]:.4g} (+/-{100 * std:.0f} %)"
                for name, std in prior.items()
            )
            method = consider.get("method", "linear")
            how = (
                "the spread of whole refits with each held value at exp(+/-std) of itself"
                if method == "refit"
                else "consider covariance, linearised at the optimum"
            )
            failed = consider.get("failed_refits", [])
            caveat = (
                f" {len(failed)} of the refits did not converge: {'; '.join(failed)}."
                if failed
                else ""
            )
            sentences.append(
                f"Held at the initial file's values, not fitted: {held}. The intervals include "
                f"this prior uncertainty of the held values ({how}); they do not assume the "
                f"held values are exact.{caveat}"
            )
        return " ".join(sentences) or None

    @property
    def initial_state_statement(self) -> str | None:
        """Which recordings started at rest (their initial state known) and which had theirs
        estimated (``FitOptions.initial_state``)."""
        if self.problem is None:
            return None
        rest = [e.name for e in self.problem.experiments if e.at_rest]
        estimated = [e.name for e in self.problem.experiments if not e.at_rest]
        parts = [f"at rest: {', '.join(rest)}"] * bool(rest)
        parts += [f"estimated: {', '.join(estimated)}"] * bool(estimated)
        return "initial states " + "; ".join(parts)

    @property
    def known_points_statement(self) -> str | None:
        """The simulation criterion of the fit against the points it knows
        (``hframe_id.fitting.known_points``), or None if they were not compared."""
        points = self.diagnostics.get("known_points")
        if not points:
            return None
        own = points["fit"]
        others = {k: v for k, v in points.items() if k != "fit"}
        label = min(others, key=others.get)
        name = self.diagnostics.get("known_points_criterion", "simulation criterion")
        return (
            f"{name} from the recordings' start: {own:.6g}; the best known point, {label}: "
            f"{others[label]:.6g}"
        )

    @property
    def multistart_statement(self) -> str | None:
        """How many starts of a multistart portfolio reached the best optimum
        (``hframe_id.fitting.multistart``), or None without one."""
        starts = self.diagnostics.get("starts")
        return multistart_statement(starts) if starts else None

    @property
    def search_statements(self) -> tuple[str | None, ...]:
        """Where the fit started and what it was compared with: the initial states, the
        known points, the multistart portfolio (None where not applicable)."""
        return (
            self.initial_state_statement,
            self.known_points_statement,
            self.multistart_statement,
        )

    def summary(self) -> str:
        """A one-screen table: parameter, initial, fitted, 95 % interval, the jackknife's
        95 % interval (after a cross-validation), status (identified, held, at bound, poorly
        determined); then the verdict line."""
        jackknife = self.has_jackknife
        extra = f" {'jackknife 95 % interval':>25}" if jackknife else ""
        lines = [
            f"{'parameter':<22} {'initial':>11} {'fitted':>11} {'95 % interval':>25}{extra}  status"
        ]
        for est in self.estimates.values():
            if not est.free:
                continue
            if not self.success:
                status = "not assessed (fit failed)"
            elif est.open_ended:
                status = f"not bounded {est.open_ended} by the data (on the box)"
            elif est.at_bound:
                status = "at bound (the box fixes it)"
            elif est.identified:
                status = "identified"
            elif est.name in self.not_identified:
                status = "NOT identified (held)"
            else:
                status = f"poorly determined (relative std {est.relative_std:.0%})"
            if est.name in self.prior_names:
                status += ", with a prior"
            if jackknife:
                ci = est.jackknife_ci95
                extra = f" [{ci[0]:>10.5g}, {ci[1]:>10.5g}]" if ci else f" {'n/a':>25}"
            lines.append(
                f"{est.key:<22} {est.initial:>11.5g} {est.estimate:>11.5g} "
                f"[{est.ci95[0]:>10.5g}, {est.ci95[1]:>10.5g}]{extra}  {status}"
            )
        lines += [s for s in self.search_statements if s]
        lines.append(
            f"{'success' if self.success else 'FAILED'}: {self.message} "
            f"(cost {self.cost:.6g}, residual rms {self.residual_rms:.3g} x the weights' "
            f"noise std, {self.residual_rms_sensor:.3g} x the sensors', "
            f"{self.iterations} iterations in all stages, {self.wall_time_s:.2f} s)"
        )
        return "\n".join(lines)


def _equation_error_report(seconds: float, used: bool) -> StageReport:
    return StageReport(
        name="equation error",
        smoothing=(math.nan, math.nan),
        iterations=0,
        converged=True,
        message="regression on differentiated data: "
        + ("used as the start" if used else "worse than the given start, not used"),
        cost=math.nan,
        max_defect=math.nan,
        wall_time_s=seconds,
    )


def _progress_sink(options: FitOptions):
    if options.progress is not None:
        return options.progress
    if options.verbose:

        def printer(p: FitProgress) -> None:
            print(
                f"  {p.stage:<30} it {p.iteration:3d}  cost {p.cost:12.6g}  "
                f"step {p.step:8.1e}  defect {p.defect:8.1e}"
                + (f"  {p.message}" if options.verbose > 1 else ""),
                file=sys.stderr,
                flush=True,
            )

        return printer
    return None


def _scaled(smoothing: tuple[float, float], factor: float) -> tuple[float, float]:
    return (smoothing[0] * factor, smoothing[1] * factor)


def _stats(gn: GaussNewton, state: SolverState, problem: FitProblem) -> Statistics:
    ev = state.evaluation
    jac, residual, blocks = gn.condensed_jacobian(ev, state.nodes, state.active)
    n_nuisance = gn.ms.n_nuisance
    names = tuple(n for n, a in zip(problem.free_names, state.active, strict=True) if a)
    return compute_statistics(jac, residual, blocks, n_nuisance, names, problem.options.uncertainty)


def _penalty_stage(
    gn: GaussNewton,
    state: SolverState,
    smoothing: tuple[float, float],
    options: FitOptions,
    windows: str,
) -> StageReport:
    """Continuity as a penalty (see PENALTY_WEIGHT): brings far-off nodes into the basin of
    the exact condensed iteration, stopping once an iteration gains under PENALTY_COST_RTOL."""
    return gn.run(
        state,
        f"{windows}, continuity as penalty",
        smoothing,
        options.max_iterations,
        INTERMEDIATE_STEP_TOL,
        math.inf,
        cost_rtol=PENALTY_COST_RTOL,
        radius=1.0,
        penalty=PENALTY_WEIGHT,
    )


def fit_recordings(
    recordings: list[Recording], initial: ParameterSet, options: FitOptions | None = None
) -> FitResult:
    """Fit a model's parameters to one or more recordings jointly (multiple shooting).

    Each channel is weighted by the sensor's noise (``options.channel_std`` or the rig's
    noise model) or, where the model cannot follow the data at that level (``options.noise``,
    see ``_estimate_noise``), by noise levels estimated from the residuals.

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
        valid samples).
    """
    options = (options or FitOptions()).for_model(initial.variant)
    start = time.perf_counter()
    if options.starts > 1:
        result = _portfolio(recordings, initial, options)
    else:
        result = _fit_widening(recordings, initial, options)
    # The known points are judged by simulation from the recordings' start: the criterion of
    # an output-error fit. A prediction-error fit (continuity "none", for plants whose
    # simulation drifts) has no such criterion to compare by.
    if options.continuity == "exact":
        result = _never_worse_than_known(recordings, initial, options, result)
    result.wall_time_s = time.perf_counter() - start
    return result


def _portfolio(recordings, initial: ParameterSet, options: FitOptions) -> FitResult:
    """The fit from ``initial`` and from ``options.starts - 1`` seeded draws around it
    (``multistart``), one after another; the best successful one by its file's criterion
    (the first's if none succeeded), with every start's outcome in ``diagnostics["starts"]``."""
    progress = _progress_sink(options)
    first = _fit_widening(recordings, initial, options)
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
        labelled = replace(options, progress=_labelled(progress, label)) if progress else options
        results.append((label, _started_from(_fit_widening(recordings, start, labelled), initial)))
    outcomes = judged(results, Criterion.of(first, recordings))
    k = min(range(len(outcomes)), key=lambda i: outcomes[i].criterion)
    best = results[k][1]
    best.diagnostics["starts"] = outcomes
    return best


def _fit_widening(recordings, initial: ParameterSet, options: FitOptions) -> FitResult:
    """The fit within the default box, repeated from ``initial`` while it ends on it
    (``BOX_WIDENINGS`` times): once a nonnegative parameter ends on its log-scale lower bound
    every free nonnegative one reaches 0 (``FitOptions.zero_reachable``: friction terms trade
    against each other, one at a time would take a fit per term), any other on the box widens
    it (bound factor squared). Still on the box after that, a failure saying so. (Restarting
    from where the last fit ended was measured worse: the linear hframe-20 plant then ended
    with F_c_bridge on the box, 1.53 x the reduction's training cost, in 77 s against 36 s.)"""
    for _ in range(BOX_WIDENINGS):
        result = _fit_in_box(recordings, initial, options, may_widen=True)
        boxed = result.diagnostics["at_default_box"]
        if not boxed:
            return result
        options = _widened(options, result, boxed)
    result = _fit_in_box(recordings, initial, options)
    boxed = result.diagnostics["at_default_box"]
    if not (boxed and result.success):
        return result
    ends = open_ends(result, recordings, boxed)
    if all(end.open for end in ends):
        return _with_open_ends(result, ends)
    return replace(
        result,
        success=False,
        message=f"the default box decided the answer: {', '.join(boxed)} ended on a "
        f"bound of x/÷{options.bound_factor:g} of the start after {BOX_WIDENINGS} "
        "widenings (the data push them further: a start closer to the rig, or "
        "--bounds, decides instead; "
        + "; ".join(end.statement() for end in ends)
        + "); "
        + result.message,
    )


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
    message = result.message.replace(_at_bound_clause(at_bound), _at_bound_clause(still))
    message += "; open-ended: " + "; ".join(end.statement() for end in ends)
    return replace(result, estimates=estimates, message=message)


def _at_bound_clause(names: list[str]) -> str:
    """The clause of a fit's message naming the parameters a bound stopped ("" if none)."""
    if not names:
        return ""
    return (
        f"; at a bound (the box, not the data, ends them there; their intervals stop at it; "
        f"--bounds widens it): {', '.join(names)}"
    )


def _started_from(result: FitResult, initial: ParameterSet) -> FitResult:
    """``result`` reporting ``initial`` as its start (a fit continued from a known point)."""
    if result.initial is initial:
        return result
    estimates = {
        name: replace(est, initial=float(initial.values[name]))
        for name, est in result.estimates.items()
    }
    return replace(result, initial=initial, estimates=estimates)


def _widened(options: FitOptions, result: FitResult, boxed: tuple[str, ...]) -> FitOptions:
    """``options`` with the default box opened for the ``boxed`` parameters of ``result``: a
    nonnegative one below its start makes every free nonnegative parameter reach 0, any
    other widens the bound factor."""
    kinds = {spec.name: spec.kind for spec in result.problem.model.parameters}
    friction = [n for n in result.problem.free_names if kinds[n] == "nonnegative"]
    to_zero = [
        n
        for n in boxed
        if n in friction and result.estimates[n].estimate < result.estimates[n].initial
    ]
    widen = set(boxed) - set(to_zero)
    zero = tuple(dict.fromkeys(options.zero_reachable + (tuple(friction) if to_zero else ())))
    return replace(
        options,
        zero_reachable=zero,
        bound_factor=options.bound_factor**2 if widen else options.bound_factor,
    )


def _known_candidates(recordings, initial: ParameterSet, options: FitOptions, result):
    """(label, parameter set) of the points a fit must not end worse than
    (``known_points``): the start, the equation-error estimate, the model's reference files
    and the user's ``FitOptions.known_points``, each with the start's fixed parameters and its
    free values clipped into the user's bounds; sets equal in their free values once."""
    problem = result.problem
    ms = MultipleShooting(problem)
    ms.initial_nodes(problem.p_initial)  # the measured positions the regression needs
    thetas = [
        ("the start", np.zeros(len(problem.free))),
        (
            "the equation-error estimate",
            equation_error_start(problem, ms.measured_positions, ms.measured_usable),
        ),
        *((label, problem.theta_of(p)) for label, p in reference_sets(initial.variant)),
        *(
            (f"known point {i + 1} ({p.title})", problem.theta_of(p))
            for i, p in enumerate(options.known_points)
        ),
    ]
    # The user's bounds and physics (0 of a friction fitted linearly) hold for every point the
    # fit may continue from; the default box, drawn around the start, does not.
    lower = np.where(problem.box_lower, -np.inf, problem.theta_lower)
    upper = np.where(problem.box_upper, np.inf, problem.theta_upper)
    unique = {}
    for label, theta in thetas:
        values = problem.parameters(np.clip(theta, lower, upper))
        free = {n: float(values[i]) for i, n in zip(problem.free, problem.free_names, strict=True)}
        unique.setdefault(tuple(free.values()), (label, initial.replace_values(**free)))
    return list(unique.values())


def _never_worse_than_known(recordings, initial, options, result) -> FitResult:
    """The fit judged against the points it knows (``known_points``) by the criterion of its
    written file (a free-run simulation of each record from the fit's initial state,
    ``known_points.Criterion``): ended worse than one, it continues from the best of them;
    worse still, it fails saying so. A fit that failed continues from the best point other
    than its start (where it has already failed) if that point simulates the data better
    than the failed fit's end."""
    criterion = Criterion.of(result, recordings)
    # Every point starts where the fit's trajectory does: its estimated initial state (a
    # record at rest: velocities zero, positions within a sensor's resolution of the
    # replay's). That favours the fit, so a point that still beats it is better.
    starts = list(result.initial_states)
    # A failed fit's end point is a point it knows too: a continuation must beat it (dev
    # plant 10: a fit failed on the box, continued from the equation-error estimate, ended
    # 300 x the reduction's training criterion; the failed fit's point simulated better).
    own = criterion(result.parameters, starts)
    candidates = _known_candidates(recordings, initial, options, result)
    if not result.success:
        candidates = [(label, params) for label, params in candidates if label != "the start"]
    if not candidates:
        return result
    points = known_points(candidates, criterion, starts)
    best = points[0]
    report = {"fit": own, **{p.label: p.criterion for p in points}}
    result.diagnostics["known_points_criterion"] = criterion.name
    # Differences under LIKELIHOOD_RATIO_95 are not significant at 95 %: such a point is not
    # better, and a continued fit that ends there has reached it.
    if best.criterion >= own - LIKELIHOOD_RATIO_95:
        result.diagnostics["known_points"] = report
        return result
    again = _started_from(_fit_widening(recordings, best.parameters, options), initial)
    continued = (
        criterion(again.parameters, list(again.initial_states)) if again.success else math.inf
    )
    report[f"fit continued from {best.label}"] = continued
    if continued <= best.criterion + LIKELIHOOD_RATIO_95:
        again.diagnostics["known_points"] = report
        again.diagnostics["known_points_criterion"] = criterion.name
        why = "failed" if not result.success else "ended worse"
        again.message += f"; continued from {best.label}, where the first fit {why}"
        return again
    result.diagnostics["known_points"] = report
    if not result.success:
        ended = "failed too" if not again.success else f"ended worse than it ({continued:.6g})"
        return replace(result, message=result.message + f"; a fit from {best.label} {ended}")
    return replace(
        result,
        success=False,
        message=f"did not converge: the fit ends worse than {best.label} ({criterion.name}: "
        f"{own:.6g} against {best.criterion:.6g}), and a fit continued from there ends at "
        f"{continued:.6g}",
    )


def _fit_in_box(
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
    problem = build_problem(recordings, initial, options)
    ms = MultipleShooting(problem)
    progress = _progress_sink(options)
    nodes, velocity = ms.initial_nodes(problem.p_initial)
    stages: list[StageReport] = []
    counter = {"evaluations": 0}
    # One-axis (a coordinate no output measures): first with the node states estimated at
    # the parameters held (converges from the truth on fresh plants, where the path from the
    # measured nodes left it); if that fails, the path from the measured nodes (which fits
    # the shipped pulses from Table 2.3, where the pre-pass path stalled). docs/fitting.md.
    unmeasured = _unmeasured_coordinates(ms) and options.state_prepass
    attempts = [True, False] if unmeasured else [False]
    best = None
    for prepass in attempts:
        outcome = _attempt(problem, ms, nodes, velocity, stages, counter, progress, prepass)
        state, gn, stats, held = outcome
        if stages[-1].converged or stages[-1].name == DEFERRED_STAGE:
            best = outcome
            break
        if best is None or state.evaluation.cost < best[0].evaluation.cost:
            best = outcome
    deferred = stages[-1].name == DEFERRED_STAGE
    if unmeasured and not deferred:
        best = _restarts_along_unmeasured_springs(
            problem, ms, nodes, velocity, stages, counter, progress, best
        )
    if may_widen:
        early = _result(problem, ms, best[1], best[0], stages, best[2], best[3], start)
        if early.diagnostics["at_default_box"]:
            return early
    sensor_std = problem.channel_std.copy()
    rounds = 0
    settling = None
    state = best[0]
    mismatch = deferred or ms.residual_rms(state.evaluation.cost) > MISMATCH_RMS
    if options.noise == "estimate" or (options.noise == "auto" and mismatch):
        problem, ms, best, rounds, settling = _estimate_noise(
            problem, ms, best, recordings, stages, counter, progress
        )
    state, gn, stats, held = best
    gn.evaluations = counter["evaluations"]
    result = _result(problem, ms, gn, state, stages, stats, held, start)
    result.diagnostics["noise"] = _noise_report(problem, sensor_std, result, rounds, settling)
    result = _misfit_judged(result, ms, state, sensor_std, estimated=bool(rounds))
    _include_held_uncertainty(problem, recordings, state, result)
    result.wall_time_s = time.perf_counter() - start
    return result


def _include_held_uncertainty(problem, recordings, state, result) -> None:
    """Widens the free parameters' intervals by the consider covariance of the held ones
    (``FitOptions.consider``), and records what the intervals assume."""
    options = problem.options
    names = problem.model.parameter_names
    prior = consider_priors(problem.model, options.consider)
    if options.consider is None:
        prior.update({n: HELD_PRIOR_RELATIVE_STD for n in result.not_identified})
    p = problem.parameters(state.theta)
    held = [n for n in names if n in prior and n not in result.free_names and p[names.index(n)]]
    result.diagnostics["consider"] = {"held_relative_std": {n: prior[n] for n in held}}
    if not held or not result.free_names:
        return
    if options.consider_method == "refit":
        variances, failed = _refit_consider_variances(problem, recordings, state, held, prior)
        result.diagnostics["consider"]["failed_refits"] = failed
        variances = {n: variances[problem.free_names.index(n)] for n in result.free_names}
    else:
        variances = _linear_consider_variances(problem, recordings, state, result, held, prior)
    z = result.statistics.z_value(options.confidence)
    extra = {}
    for name in result.free_names:
        est = result.estimates[name]
        f = problem.free_names.index(name)
        signed, scale = problem.linear[f], problem.linear_scale[f]
        variance = max(float(variances[name]), 0.0)
        theta_std = est.std_error / scale if signed else est.relative_std
        std, rel, ci95 = spread(est.estimate, math.sqrt(theta_std**2 + variance), signed, scale, z)
        if est.at_bound:
            ci95 = _ended_at_bound(problem, state, f, ci95)
        extra[name] = math.sqrt(variance)
        result.estimates[name] = replace(est, relative_std=rel, std_error=std, ci95=ci95)
    result.diagnostics["consider"]["relative_std_added"] = extra
    result.diagnostics["consider"]["method"] = options.consider_method


def _linear_consider_variances(problem, recordings, state, result, held, prior) -> dict:
    """Per free parameter (name), the variance (in its theta units) the held parameters' priors add,
    linearised at the optimum: diag S P S^T (``consider.consider_covariance``)."""
    names = problem.model.parameter_names
    p = problem.parameters(state.theta)
    values = {n: float(v) for n, v in zip(names, p, strict=True)}
    widened = build_problem(
        recordings,
        problem.initial.replace_values(**values),
        replace(problem.options, free=result.free_names + tuple(held), fix=(), bounds={}),
    )
    ms = MultipleShooting(widened).uniform()
    theta = np.zeros(len(widened.free))
    ev = ms.evaluate(state.nodes, theta, widened.smoothing)
    jac, _, _ = GaussNewton(ms).condensed_jacobian(ev, state.nodes, np.ones(theta.size, bool))
    n_estimated = ms.n_nuisance + len(result.free_names)
    added = consider_covariance(
        jac[:, :n_estimated], jac[:, n_estimated:], np.array([prior[n] for n in held])
    )
    offset = n_estimated - len(result.free_names)
    return {name: added[offset + k, offset + k] for k, name in enumerate(result.free_names)}


def _refit_consider_variances(
    problem, recordings, state, held, prior
) -> tuple[np.ndarray, list[str]]:
    """Per free parameter (``problem.free`` order), the variance (in its theta units) the held
    parameters' priors add, from refits: the whole fit repeated from its start with each held
    value at exp(+/-sigma) times itself, and half the difference of the two estimates taken as
    that prior's one-sigma effect. A held idler 15 % off moved the one-axis fit's B_1 by +52 %
    where the tangent at the optimum predicts 5 %, and warm-started refits (which stay in the
    optimum's basin) covered no better than the tangent (docs/fitting.md). Also returns the
    refits that did not converge ("name xfactor: message"); their ends count all the same,
    stated in the held statement.
    """
    names = problem.model.parameter_names
    p = problem.parameters(state.theta)
    quiet = replace(problem.options, consider={}, verbose=0, progress=None)
    variances = np.zeros(len(problem.free))
    failed = []
    for name in held:
        ends = []
        for sign in (1.0, -1.0):
            factor = math.exp(sign * prior[name])
            value = float(p[names.index(name)]) * factor
            refit = fit_recordings(
                recordings, problem.initial.replace_values(**{name: value}), quiet
            )
            if not refit.success:
                failed.append(f"{name} x{factor:.3g}: {refit.message}")
            ends.append(problem.theta_of(refit.parameters))
        variances += ((ends[0] - ends[1]) / 2.0) ** 2
    return variances, failed


def _estimate_noise(problem, ms, best, recordings, stages, counter, progress):
    """Channel noise levels by maximum likelihood: the fit is repeated with each channel's std
    set to its residual rms at the last optimum (floored at the sensor's std), warm-started
    from the last nodes and parameters, until no std changes by more than ``NOISE_RTOL``.

    With unknown channel variances the likelihood, concentrated on them, is
    L = sum_j N_j log(rms_j). Each round minimises a majoriser of L (log is concave), and
    the rounds' stages are monotone from the last optimum, so L cannot increase: a
    majorise-minimise iteration. At its fixed point the residual rms is one estimated std
    per channel, and the tolerances and acceptance tests in noise units measure against
    what the model can do rather than the sensor (model error is 100-1000x the encoder's
    step on the realistic rig). Parameters held for identifiability are released and
    not held again.

    A last round that stalls is rejected, as a trust region rejects a step: the fit is the
    last converged round's optimum (a real trajectory at its weights), marked by a
    ``REJECTED_ROUND_STAGE`` stage, with the noise levels reported as not settled. A round
    before the last that stalls is re-weighted from where it stopped, as before.

    Returns (problem, transcription, (state, solver, statistics, held), rounds, settling),
    ``settling`` the largest relative change (in log) of a std over the last round and
    whether that met ``NOISE_RTOL``.
    """
    sensor_std = problem.channel_std
    state = best[0]
    state.active = np.ones(len(problem.free), dtype=bool)
    rounds = 0
    gn = best[1]
    accepted = None
    for rounds in range(1, MAX_NOISE_ROUNDS + 1):
        std = _noise_levels(ms, state, problem.channel_std, sensor_std)
        change = float(np.max(np.abs(np.log(std / problem.channel_std))))
        if rounds > 1 and change <= NOISE_RTOL and stages[-1].converged:
            rounds -= 1
            break
        weights = dict(zip(problem.output_names, std.tolist(), strict=True))
        problem = build_problem(
            recordings, problem.initial, replace(problem.options, channel_std=weights)
        )
        ms = MultipleShooting(problem)
        label = "noise round {} (std {})".format(
            rounds, ", ".join(f"{k} {v:.3g}" for k, v in weights.items())
        )
        state, gn = _warm_solve(
            ms, state.nodes, state.theta, state.active, stages, counter, progress, label
        )
        if stages[-1].converged:
            accepted = (problem, ms, state, gn, rounds)
    else:
        if not stages[-1].converged and accepted is not None:
            problem, ms, state, gn, kept = accepted
            stages.append(_rejected_round_report(stages[-1], kept, ms, state))
        std = _noise_levels(ms, state, problem.channel_std, sensor_std)
        change = float(np.max(np.abs(np.log(std / problem.channel_std))))
    settling = {"change": change, "settled": change <= NOISE_RTOL}
    # No identifiability holds here: holding a parameter at its initial value moves the
    # others away from the best approximation (docs/fitting.md, "Model mismatch"). Poorly
    # determined parameters are reported as such (``_result``), at their estimates.
    return problem, ms, (state, gn, _stats(gn, state, problem), {}), rounds, settling


def _noise_levels(ms, state, weight_std, sensor_std) -> np.ndarray:
    """The next round's noise std per channel [SI]: the residual rms at ``state``, floored at
    the sensor's std (``weight_std`` where a channel has no valid residual)."""
    rms = np.array(list(_channel_rms(ms, state.evaluation).values()))
    return np.maximum(np.where(np.isfinite(rms), rms, weight_std), sensor_std)


def _rejected_round_report(stalled: StageReport, kept: int, ms, state) -> StageReport:
    """The stage that records a stalled last noise round rejected and round ``kept``'s
    optimum taken as the fit."""
    return StageReport(
        name=REJECTED_ROUND_STAGE,
        smoothing=stalled.smoothing,
        iterations=0,
        converged=True,
        message=f"the last noise round did not converge ({stalled.message}); the fit is "
        f"noise round {kept}'s optimum, its noise levels not settled",
        cost=state.evaluation.cost,
        max_defect=float(np.max(np.abs(ms.defects(state.evaluation, state.nodes)), initial=0)),
        wall_time_s=0.0,
    )


def _warm_solve(ms, nodes, theta, active, stages, counter, progress, label):
    """Every window, exact continuity, from given nodes and parameters, monotone (no step
    may raise the merit: a warm start is kept, not thrown away by free steps). Used by the
    noise rounds: with estimated noise levels a stall counts as converged only with its
    defects at ``defect_tol`` (or closed by simulation), see ``GaussNewton.run``."""
    ms = ms.uniform()
    gn = GaussNewton(ms, progress, freeze_sloppy=True)
    state = SolverState(nodes.copy(), theta.copy(), active.copy())
    stages.append(
        _exact_stage(
            gn,
            state,
            label,
            cost_rtol=WARM_COST_RTOL,
            radius=0.5,
            watchdog=False,
            stall_defect_tol=ms.problem.options.defect_tol,
        )
    )
    counter["evaluations"] += gn.evaluations
    return state, gn


def _exact_stage(gn: GaussNewton, state: SolverState, label: str, **settings) -> StageReport:
    """Every window with exact continuity, to the options' tolerances, by the solver the
    options name: the Gauss-Newton stage (``settings`` go to ``GaussNewton.run``) or CasADi's
    IPOPT on the same transcription (``hframe_id.fitting.nlp``). Updates ``state``."""
    ms = gn.ms
    problem = ms.problem
    options = problem.options
    if options.solver == "gauss-newton":
        return gn.run(
            state,
            label,
            problem.smoothing,
            options.max_iterations,
            options.step_tol,
            options.defect_tol,
            **settings,
        )
    outcome = solve_nlp(
        ms,
        state.nodes,
        state.theta,
        state.active,
        problem.smoothing,
        NlpSettings(max_iter=options.max_iterations),
    )
    state.nodes, state.theta = outcome.nodes, outcome.theta
    state.evaluation = ms.evaluate(state.nodes, state.theta, problem.smoothing)
    state.velocity_hint = state.evaluation.states[:, :, ms.nq :]
    converged = outcome.converged and outcome.max_defect <= options.defect_tol
    return StageReport(
        name=f"{label} (IPOPT)",
        smoothing=problem.smoothing,
        iterations=outcome.iterations,
        converged=converged,
        message=("converged: " if converged else "did not converge: ") + outcome.message,
        cost=state.evaluation.cost,
        max_defect=float(np.max(np.abs(ms.defects(state.evaluation, state.nodes)), initial=0)),
        wall_time_s=outcome.wall_time_s,
        substeps=state.evaluation.n_substeps,
    )


def is_at_bound(theta: float, lower: float, upper: float, relative_std: float) -> bool:
    """Whether a free parameter (``theta`` between its bounds, theta units) is at a bound:
    within ``AT_BOUND_STD`` of its relative standard error (at most 1) of it, or 1e-9."""
    near = 1e-9 + AT_BOUND_STD * min(relative_std, 1.0)
    return theta <= lower + near or theta >= upper - near


def _misfit_judged(result: FitResult, ms, state, sensor_std: np.ndarray, estimated: bool):
    """``result`` with its residual rms in units of the sensors' noise (``sensor_std`` [SI]:
    the user's ``channel_std`` or the rig's specification, never a level estimated from the
    residuals) in ``diagnostics["residual_rms_sensor_std"]``, failed as a poor fit if that
    exceeds the misfit limit: ``FitOptions.max_misfit`` if given, else ``DEFAULT_MAX_MISFIT``
    for a fit weighted by the sensors' noise, and no limit for one that estimated its noise
    levels (model mismatch: stated with its evidence in the report, and judged against the
    points the fit knows instead)."""
    used = ms.weight > 0
    scale = ms.problem.channel_std / sensor_std
    residual = state.evaluation.residual * scale
    misfit = float(np.sqrt(np.mean(residual[used] ** 2))) if used.any() else math.nan
    result.diagnostics["residual_rms_sensor_std"] = misfit
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


def _noise_report(
    problem: FitProblem, sensor_std: np.ndarray, result, rounds: int, settling: dict | None
) -> dict:
    """Per channel: the sensor's noise std, the std the fit weighed with, and the residual
    rms in SI units and in sensor std (the mismatch statement of the report); for estimated
    levels also how far they were from their fixed point (``settling``, see
    ``_estimate_noise``)."""
    rms = result.diagnostics["channel_rms"]
    return {
        "method": "estimated" if rounds else "sensor",
        "rounds": rounds,
        **({"settling": settling} if rounds and settling is not None else {}),
        "channels": {
            name: {
                "sensor_std": float(sensor_std[j]),
                "weight_std": float(problem.channel_std[j]),
                "residual_rms": rms[name],
                "residual_rms_sensor_std": rms[name] / float(sensor_std[j]),
            }
            for j, name in enumerate(problem.output_names)
        },
    }


def _restarts_along_unmeasured_springs(
    problem, ms, nodes, velocity, stages, counter, progress, best
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
                    ms,
                    nodes,
                    velocity,
                    theta,
                    state.active.copy(),
                    trial_stages,
                    counter,
                    _labelled(progress, label),
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
        stats = _stats(gn, state, problem)
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


def _labelled(progress, label: str):
    """A progress sink that prefixes the stage name with ``label`` (None stays None)."""
    if progress is None:
        return None
    return lambda p: progress(replace(p, stage=f"{label}: {p.stage}"))


def _springs_at_unmeasured_coordinates(problem: FitProblem, ms: MultipleShooting) -> list[int]:
    """Free parameters (indices into ``problem.free``) that enter the generalised force on
    a coordinate no output measures through the potential energy (one-axis: k2, k3)."""
    model = problem.model
    x = ca.SX.sym("x", model.n_states)
    p = ca.SX.sym("p", len(model.parameters))
    _, potential = model.energy(x, p)
    unmeasured = np.flatnonzero(~np.any(ms.c[:, : ms.nq] != 0, axis=0))
    force = ca.gradient(potential, x)[unmeasured.tolist()]
    coupled = {j for j in range(p.shape[0]) if ca.depends_on(force, p[j])}
    return [f for f, i in enumerate(problem.free) if i in coupled]


def _attempt(problem, ms, nodes, velocity, stages, counter, progress, prepass):
    """Equation-error start, output-error stages and the identifiability holds, from the
    given start (with the state-estimation pre-pass if ``prepass``)."""
    options = problem.options
    start = time.perf_counter()
    n_free = len(problem.free)
    theta = np.zeros(n_free)
    smoothing = problem.smoothing
    if options.first_stage:
        regressed = equation_error_start(problem, ms.measured_positions, ms.measured_usable)
        # Keep the regression only if it fits the data better than the given start does
        # (both judged by the output error of independent shooting windows: one evaluation
        # each). It is biased and can be poor where a coordinate is not measured.
        if prepass:
            # Judged after estimating the node states at each: from the measured nodes (an
            # unmeasured coordinate on the rigid motion) the truth itself can lose to a
            # poorer regression (docs/fitting.md, "One-axis").
            active0 = np.ones(n_free, dtype=bool)
            trials = [
                _estimate_states(ms, nodes, velocity, th, active0, [], progress)
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
        stages.append(_equation_error_report(time.perf_counter() - start, used))
    active = np.ones(n_free, dtype=bool)
    state, gn = _solve(
        problem, ms, nodes, velocity, theta, active, stages, counter, progress, prepass, True
    )
    stats = _stats(gn, state, problem)
    if options.noise != "sensor" and ms.residual_rms(state.evaluation.cost) > MISMATCH_RMS:
        # Model mismatch: identifiability is decided after the noise levels are estimated.
        return state, gn, stats, {}

    def resolve(theta, active):
        # Holding a parameter that had wandered along a sloppy valley moves the optimum of
        # the others (its collinear partners compensate): solve again from the measured
        # nodes, with the other parameters where they were.
        return _solve(
            problem, ms, nodes, velocity, theta, active, stages, counter, progress, prepass
        )

    return _hold_unidentified(problem, ms, state, gn, stats, stages, resolve)


def _hold_unidentified(problem, ms, state, gn, stats, stages, resolve):
    """Holds free parameters whose relative standard error exceeds the identifiability
    threshold at their initial value, the worst first, and solves again with
    ``resolve(theta, active) -> (state, solver)``, until every parameter left is identified.
    Returns (state, solver, statistics, held)."""
    options = problem.options
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
        stats = _stats(gn, state, problem)
    return state, gn, stats, held


def _solve(
    problem,
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
    options = problem.options
    smoothing = problem.smoothing
    schedule = options.smoothing_schedule
    theta = theta.copy()
    if prepass:
        nodes, _ = _estimate_states(ms, nodes, velocity, theta, active, stages, progress)
    measured = nodes
    nodes = nodes.copy()
    mismatch = False
    # Stages on the windows where something moves: they carry the dynamics, and leaving out
    # the stiff stretches at rest makes each evaluation several times cheaper.
    moving = ms.moving_windows(velocity, smoothing) if options.first_stage else np.arange(0)
    if 0 < moving.size < ms.n_windows:
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
                    _penalty_stage(
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
    ms = ms.uniform()
    if prepass and moving.size and not mismatch:
        # The nodes at rest were simulated with the moving-window parameters, which put an
        # unmeasured pulley's stretch wherever those left it: estimate them again with the
        # parameters held (docs/fitting.md, "One-axis", the second pre-pass). Not under
        # mismatch: there the pre-pass (continuity a penalty) follows the data with a
        # discontinuous trajectory, and the noise rounds would estimate the noise from it
        # (realistic one-axis plant 2: defects of 79 sensor std, noise 33 sensor std where
        # continuous trajectories are at 0.2-3 rad) and stall (docs/fitting.md).
        nodes, _ = _estimate_states(ms, nodes, velocity, theta, active, stages, progress)
    gn = GaussNewton(ms, progress, freeze_sloppy=True)
    if mismatch:
        # The model does not follow the data at the sensors' noise level: the weights are
        # wrong by orders of magnitude, so the all-window stages are left to the noise
        # rounds (``_estimate_noise``), which start from here.
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
    # (IPOPT, ``FitOptions.solver``, globalises by itself: no fallback.)
    for use_penalty in (False, True)[: 1 if options.solver == "ipopt" else 2]:
        start_nodes = measured if use_penalty else nodes
        state = SolverState(start_nodes.copy(), theta.copy(), active.copy(), velocity_hint=velocity)
        if use_penalty:
            stages.append(_penalty_stage(gn, state, smoothing, options, "all windows"))
        stages.append(_exact_stage(gn, state, "all windows", radius=0.5))
        if stages[-1].converged:
            break
    counter["evaluations"] += gn.evaluations
    return state, gn


def _unmeasured_coordinates(ms: MultipleShooting) -> bool:
    """Whether some coordinate is measured by no output (one-axis: the idler pulley)."""
    seen = np.any(ms.c[:, : ms.nq] != 0, axis=0)
    return not bool(np.all(seen))


def _estimate_states(ms, nodes, velocity, theta, active, stages, progress):
    """State-estimation pre-pass: the node states with the parameters held at ``theta``.

    The nodes from the data put unmeasured coordinates (and lasers out of range) on the
    rigid motion (belts unstretched); the continuity defects that leaves make the first
    Gauss-Newton steps in the parameters large (0.3-0.4 in log p even at the truth). Here
    continuity is a penalty and only the nodes move; the parameters are released after.
    """
    gn = GaussNewton(ms, progress)
    state = SolverState(nodes.copy(), theta.copy(), np.zeros_like(active), velocity_hint=velocity)
    stages.append(
        gn.run(
            state,
            "state estimation",
            ms.problem.smoothing,
            PREPASS_ITERATIONS,
            INTERMEDIATE_STEP_TOL,
            INTERMEDIATE_DEFECT_TOL,
            cost_rtol=PREPASS_COST_RTOL,
            radius=1.0,
            penalty=PENALTY_WEIGHT,
        )
    )
    ev = state.evaluation
    merit = ev.cost + 0.5 * PENALTY_WEIGHT * float(np.sum(ms.defects(ev, state.nodes) ** 2))
    return state.nodes, merit


def _ended_at_bound(problem, state, f: int, ci95: tuple[float, float]) -> tuple[float, float]:
    """The interval of free parameter ``f`` (at a bound) cut at that bound [SI]: the box
    allowed no values beyond it."""
    lower = state.theta[f] - problem.theta_lower[f] < problem.theta_upper[f] - state.theta[f]
    theta = state.theta.copy()
    theta[f] = problem.theta_lower[f] if lower else problem.theta_upper[f]
    bound = float(problem.parameters(theta)[problem.free[f]])
    return (bound, max(ci95[1], bound)) if lower else (min(ci95[0], bound), bound)


def spread(
    value: float, theta_std: float, signed: bool, scale: float, z: float
) -> tuple[float, float, tuple[float, float]]:
    """(std error [SI], relative std, interval) of a free parameter from the std of its theta.

    Log-scale parameters: theta is a relative change, the interval symmetric in log(p),
    [p / f, p f] with f = exp(z std). Linear ones (``signed``: nonnegative and real kinds):
    p = p0 + s theta, the interval p -/+ z s std.
    """
    if signed:
        std = scale * theta_std
        return std, std / abs(value) if value else math.inf, (value - z * std, value + z * std)
    factor = math.exp(min(z * theta_std, 700.0))
    return value * theta_std, theta_std, (value / factor, value * factor)


def _result(problem, ms, gn, state, stages, stats, held, start) -> FitResult:
    options = problem.options
    final = stages[-1]
    p = problem.parameters(state.theta)
    names = problem.model.parameter_names
    specs = {s.name: s for s in problem.model.parameters}
    z = stats.z_value(options.confidence)
    estimates: dict[str, ParameterEstimate] = {}
    at_bound, at_box = [], []
    active_names = stats.names
    for i, name in enumerate(names):
        spec = specs[name]
        value = float(p[i])
        initial_value = float(problem.p_initial[i])
        if i not in problem.free:
            estimates[name] = ParameterEstimate(
                name, spec.unit, initial_value, value, 0.0, (value, value), False, False
            )
            continue
        f = problem.free.index(i)
        if name in active_names:
            k = active_names.index(name)
            rel, rel_gn, col = (
                float(stats.relative_std[k]),
                float(stats.relative_std_gn[k]),
                float(stats.collinearity[k]),
            )
            identified = rel <= options.identifiability_threshold
        else:
            rel, rel_gn, col = held.get(name, (math.inf, math.inf, math.inf))
            identified = False
        bound = bool(state.active[f]) and is_at_bound(
            state.theta[f], problem.theta_lower[f], problem.theta_upper[f], rel
        )
        floor = problem.zero_floor[f] and state.theta[f] < 0
        if bound and floor:  # at zero: physics ends it there, not the box
            bound = False
        if bound:  # the box, not the data, fixes it
            at_bound.append(name)
            identified = False
            if problem.on_box(state.theta)[f]:
                at_box.append(name)
        std, rel, ci95 = spread(value, rel, problem.linear[f], problem.linear_scale[f], z)
        if bound:
            ci95 = _ended_at_bound(problem, state, f, ci95)
        elif problem.zero_floor[f]:
            ci95 = (max(ci95[0], 0.0), ci95[1])
        estimates[name] = ParameterEstimate(
            name=name,
            unit=spec.unit,
            initial=initial_value,
            estimate=value,
            std_error=std,
            ci95=ci95,
            identified=identified,
            free=True,
            relative_std=rel,
            relative_std_gn=rel_gn,
            collinearity=col,
            at_bound=bound,
        )
    not_identified = tuple(n for n in problem.free_names if n in held)
    if not_identified:
        # Imported here: the standard designs read the shipped datasets' protocols (0.15 s).
        from hframe_id.fitting.design_advice import identifying_designs

        advice = identifying_designs(problem, ms, gn, state, stats, not_identified)
        for name, designs in advice.items():
            estimates[name] = replace(estimates[name], identified_by=designs)
    misfit = ms.residual_rms(state.evaluation.cost)
    success = final.converged
    if not final.converged:
        message = f"did not converge: {final.message}"
    else:
        message = final.message
        message += _at_bound_clause(at_bound)
        if not_identified:
            message += f"; not identified (held at initial value): {', '.join(not_identified)}"
        poorly = [n for n in stats.names if not estimates[n].identified and n not in at_bound]
        if poorly:
            message += (
                f"; poorly determined (relative std > {options.identifiability_threshold:.0%}, "
                f"kept at their estimates): {', '.join(poorly)}"
            )
    values = {n: float(v) for n, v in zip(names, p, strict=True)}
    values.update({k: v for k, v in problem.initial.values.items() if k not in values})
    parameters = ParameterSet(
        variant=problem.initial.variant,
        values=values,
        title=f"{problem.initial.variant} fitted to {len(problem.experiments)} recording(s)",
        source="hframe-id fit (multiple shooting, Gauss-Newton)",
        references=list(problem.initial.references),
    )
    first = ms.first_window
    return FitResult(
        success=success,
        message=message,
        parameters=parameters,
        estimates=estimates,
        cost=float(state.evaluation.cost),
        iterations=int(sum(s.iterations for s in stages)),
        wall_time_s=time.perf_counter() - start,
        correlation=stats.correlation,
        free_names=stats.names,
        initial=problem.initial,
        options=options,
        stages=stages,
        statistics=stats,
        not_identified=not_identified,
        initial_states=state.nodes[first].copy(),
        experiment_names=tuple(e.name for e in problem.experiments),
        evaluations=gn.evaluations,
        problem=problem,
        diagnostics={
            "channel_std": dict(
                zip(problem.output_names, problem.channel_std.tolist(), strict=True)
            ),
            "channel_rms": _channel_rms(ms, state.evaluation),
            "noise_scale": stats.noise_scale,
            "hac_bandwidths": stats.bandwidths,
            "collinearity_of_set": stats.collinearity_set,
            "max_defect": final.max_defect,
            "residual_rms_noise_std": misfit,
            "substeps": list(final.substeps),
            "at_default_box": tuple(at_box),
        },
    )


def _channel_rms(ms: MultipleShooting, ev) -> dict[str, float]:
    """Residual rms of each output channel over its valid samples, in SI units."""
    problem = ms.problem
    used = ms.weight > 0
    rms = {}
    for j, name in enumerate(problem.output_names):
        n = int(np.count_nonzero(used[:, :, j]))
        weighted = float(np.sum(ev.residual[:, :, j][used[:, :, j]] ** 2))
        rms[name] = math.sqrt(weighted / n) * float(problem.channel_std[j]) if n else math.nan
    return rms
