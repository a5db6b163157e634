"""Gauss-Newton (Levenberg-Marquardt) on the lifted multiple-shooting problem.

One kind of stage, ``continuity``, on ``MultipleShooting.evaluate``, in two forms (their
linearisations: ``fitting.condensed``): exact continuity, condensed, under a watchdog on the
merit that globalises the step (the nonlinear defects close as the iteration converges); or
continuity as a penalty, a monotone trust-region fallback that takes a poor start into the
exact form's basin. Parameters stay within their bounds by projection: a parameter at a
bound whose step points outward is held for that iteration.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hframe_id.fitting.condensed import CondensedModel
from hframe_id.fitting.gauss_newton_settings import GaussNewtonSettings
from hframe_id.fitting.options import FitProgress
from hframe_id.fitting.shooting import Evaluation, MultipleShooting
from hframe_id.fitting.stiffness_wall import StiffnessWall
from hframe_id.fitting.substep_plan import stopped_message
from hframe_id.fitting.trust_region import bounded_step

#: A free log-parameter this close to a bound is on it (rounding of the projection).
AT_BOUND = 1e-9


@dataclass
class SolverState:
    """Iterate of the lifted problem."""

    nodes: np.ndarray  # (W, n_x)
    theta: np.ndarray  # (n_f,) log-parameters of the free parameters
    active: np.ndarray  # (n_f,) bool: parameter is being fitted (False: held at prior)
    evaluation: Evaluation | None = None
    velocity_hint: np.ndarray | None = None


@dataclass
class StageReport:
    """How one stage ended: its name, smoothing velocities (v_s [m/s], [rad/s]), iterations,
    convergence and message, cost (chi^2 / 2), largest continuity defect (noise std), wall
    time [s], free parameters at a bound (indices), substeps (fewest, most) per sample and
    the final trust-region radius."""

    name: str
    smoothing: tuple[float, float]
    iterations: int
    converged: bool
    message: str
    cost: float
    max_defect: float
    wall_time_s: float
    at_bound: list[int] = field(default_factory=list)
    substeps: tuple[int, int] = (0, 0)
    radius: float = math.nan

    @classmethod
    def verdict(
        cls, name: str, after: StageReport, message: str, cost: float, max_defect: float
    ) -> StageReport:
        """A stage that records a decision on the stages before it, ``after`` the last of them
        (its smoothing): no iterations, no time, converged at the end the fit keeps (its
        ``cost`` and ``max_defect``)."""
        return cls(name, after.smoothing, 0, True, message, cost, max_defect, 0.0)


def _watchdog_verdict(
    ratio: float, new: float, current: float, best: float, free: bool, factor: float
) -> tuple[float, bool]:
    """(ratio the trust region adapts to, accepted) for an exact stage's step under the
    watchdog, from its merit ratio (actual / predicted decrease) and the merits ``new``,
    ``current`` before it and ``best`` so far. Accepted: any finite merit in the ``free``
    first steps (they close the last stage's defects), then one below ``factor`` x best.
    The region shrinks only on an increase, and on every refusal: a step refused with the
    region unchanged is tried again, forever (issue 25's test plant 1262: the current merit
    above ``factor`` x best after mu rose, steps halving it refused for 35 min)."""
    if not np.isfinite(new):
        return ratio, False
    if not (free or new < factor * best):
        return -1.0, False
    return (max(ratio, 0.5) if new <= current else ratio), True


def _penalty_parameter(mu: float, change: float, l1: float, rho: float) -> float:
    """The l1 penalty parameter for a step that closes the linearised defects.

    The step changes the model cost by ``change`` (chi^2 / 2 units) and removes the defects
    ``l1`` = |defects|_1 (noise units). It must predict a merit decrease of at least
    ``rho`` times the penalty removed (Nocedal & Wright, eq. 18.36): mu is raised to
    ``change / ((1 - rho) l1)`` where it is smaller, and never lowered.
    """
    if l1 <= 0 or change <= (1 - rho) * mu * l1:
        return mu
    return change / ((1 - rho) * l1)


def _determined(h_red: np.ndarray, sloppy_std: float) -> np.ndarray:
    """Parameters whose textbook relative std (from the reduced information, residuals in
    noise units) is at most ``sloppy_std``."""
    if h_red.size == 0:
        return np.ones(0, dtype=bool)
    d = np.sqrt(np.maximum(np.diag(h_red), 1e-300))
    cov = np.linalg.pinv(h_red / np.outer(d, d), rcond=1e-12, hermitian=True) / np.outer(d, d)
    return np.sqrt(np.maximum(np.diag(cov), 0.0)) <= sloppy_std


@dataclass
class _Walk:
    """Where one stage's iteration stands between steps (``GaussNewton.run``).

    The merit of exact stages is the l1 exact penalty cost + mu |defects|_1 (noise units),
    mu raised so that every full step predicts a decrease (``_penalty_parameter``): unlike a
    fixed quadratic penalty, whose minimiser leaves defects of the size of the multipliers
    (hundreds of noise std when the model cannot follow the data), its minimiser is the
    continuous trajectory. Penalty stages: the quadratic penalty. ``best``: (merit, nodes,
    theta, evaluation) of the best iterate; ``predicted``: the merit decrease the model
    predicted for the last step tried."""

    ms: MultipleShooting
    links: np.ndarray
    penalty: float | None
    radius: float
    monotone: bool
    mu: float = 1.0
    best: tuple = ()
    best_history: list = field(default_factory=list)
    costs: list = field(default_factory=list)
    reverts: int = 0
    since_best: int = 0
    predicted: float = math.inf

    def merit(self, ev: Evaluation, nodes: np.ndarray) -> float:
        """The stage's merit at ``nodes`` evaluated as ``ev``."""
        defects = self.ms.defects(ev, nodes, self.links)
        if self.penalty is None:
            return ev.cost + self.mu * float(np.sum(np.abs(defects)))
        return ev.cost + 0.5 * self.penalty * float(np.sum(defects**2))


@dataclass
class _Trial:
    """One iteration's step (``GaussNewton._trial``): accepted or not, its largest parameter
    change, whether the trust region left it whole, the merit before it, and where it led."""

    current: float
    accepted: bool = False
    full_step: bool = False
    overflowed: bool = False
    step: float = 0.0
    nodes: np.ndarray | None = None
    theta: np.ndarray | None = None
    evaluation: Evaluation | None = None


class GaussNewton(CondensedModel):
    """Iterates the stages of the lifted problem (its linearisation: ``CondensedModel``)."""

    def __init__(
        self,
        shooting: MultipleShooting,
        progress=None,
        freeze_sloppy: bool = False,
        settings: GaussNewtonSettings | None = None,
    ):
        super().__init__(shooting)
        #: The iteration's tuning (default: ``GaussNewtonSettings()``).
        self.settings = settings or GaussNewtonSettings()
        self.progress = progress
        self.evaluations = 0
        #: Hold undetermined parameters still (final stages, where the iterate is near an
        #: optimum; far from it a parameter can look undetermined only transiently).
        self.freeze_sloppy = freeze_sloppy

    def _evaluate(
        self, state: SolverState, nodes, theta, smoothing, derivatives: bool = True
    ) -> Evaluation:
        """The transcription at (nodes, theta), its windows split by ``state``'s velocity hint;
        without ``derivatives``, residuals only (a trial step, judged by its merit alone)."""
        self.evaluations += 1
        return self.ms.evaluate(
            nodes, theta, smoothing, velocity_hint=state.velocity_hint, derivatives=derivatives
        )

    def _close_by_simulation(self, state: SolverState, ev: Evaluation, smoothing, merit_now):
        """At a stall with small defects left (typically velocities at rest, where closing
        them is nonlinear), replace the nodes by one simulation per experiment from its
        initial state. If that continuous trajectory fits as well as the lifted iterate
        (cost within ``settings.close_cost_tol``, in units of chi^2 / 2), it is the solution."""
        ms = self.ms
        known = np.zeros(ms.n_windows, dtype=bool)
        known[np.flatnonzero(np.r_[True, ~self.links])] = True
        nodes = ms.fill_nodes(state.nodes, known, state.theta, smoothing)
        trial = self._evaluate(state, nodes, state.theta, smoothing)
        if not np.isfinite(trial.cost) or trial.cost > merit_now + self.settings.close_cost_tol:
            return None
        state.nodes = nodes
        state.evaluation = trial
        state.velocity_hint = trial.states[:, :, ms.nq :]
        return trial

    # ------------------------------------------------------------------ driver
    def run(
        self,
        state: SolverState,
        stage: str,
        smoothing: tuple[float, float],
        max_iterations: int,
        step_tol: float,
        defect_tol: float,
        cost_rtol: float = 0.0,
        radius: float = 0.5,
        penalty: float | None = None,
        watchdog: bool = True,
        give_up: int | None = None,
        stall_defect_tol: float | None = None,
        interrupt: Callable[[Evaluation, float], str | None] | None = None,
    ) -> StageReport:
        """Iterate one stage until converged; updates ``state`` in place.

        ``stage`` names the stage in progress reports. Exact continuity (``penalty`` None):
        nearly full Gauss-Newton steps under a watchdog (see the module docstring); with
        ``penalty``: continuity as weighted residuals, monotone trust region.

        Converged: the last step was a full Gauss-Newton step (trust region inactive) that
        changed no free parameter by more than ``step_tol`` (relative), and the continuity
        defects are below ``defect_tol`` (noise units). A stage may also stop once an
        iteration lowers the cost by less than ``cost_rtol`` (relative; exact stages: on
        average over ``settings.cost_window`` iterations, with the defects below ``defect_tol``).
        With ``give_up``, a stage far from the noise level that stops making progress ends
        unconverged early (for fast paths that have a fallback). A stall at the noise level
        with every defect below ``stall_defect_tol`` (default ``settings.stall_defect_tol``)
        is accepted too, unless a simulation from
        the initial states closes them as well (``_close_by_simulation``); where the noise
        levels are estimated from the residuals (model error) the caller passes
        ``defect_tol`` (no such acceptance): defects of 2 estimated std let a discontinuous
        trajectory follow data its model cannot.

        ``interrupt(evaluation, decrease over the last cost_window)``, asked in exact stages
        with the defects at ``defect_tol``, ends the stage, converged, with its message if any.
        """
        start = time.perf_counter()
        ms = self.ms
        settings = self.settings
        if stall_defect_tol is None:
            stall_defect_tol = settings.stall_defect_tol
        self.node_damping = settings.node_damping
        self.set_smoothing(smoothing, settings.proximal_weight)
        self.links = ms.linked.copy()
        ev = self._evaluate(state, state.nodes, state.theta, smoothing)
        state.evaluation = ev
        state.velocity_hint = ev.states[:, :, ms.nq :]
        converged = False
        message = f"not converged in {max_iterations} iterations"
        iterations = 0
        # Exact stages start with the watchdog; once it has had to step back, they continue
        # as a monotone trust-region method (so they cannot cycle).
        walk = _Walk(ms, self.links, penalty, radius, penalty is not None or not watchdog)
        walk.best = (walk.merit(ev, state.nodes), state.nodes, state.theta, ev)
        walk.costs.append(ev.cost)
        for iterations in range(1, max_iterations + 1):
            trial = self._trial(walk, state, smoothing, iterations)
            if trial.accepted:
                self._accept(walk, state, trial, iterations)
            ev = state.evaluation
            if trial.overflowed:
                message = stopped_message(ev.n_substeps[1], ms.transcription.max_substeps)
                break
            max_defect = float(np.max(np.abs(ms.defects(ev, state.nodes, self.links)), initial=0))
            self._report_progress(stage, smoothing, iterations, ev, trial.step, max_defect, walk)
            if not trial.accepted:
                converged, message, ev = self._stalled(
                    walk, state, smoothing, defect_tol, stall_defect_tol, trial.current
                )
                break
            walk.best_history.append(walk.best[0])
            if give_up is not None and self._gives_up(walk, ev, give_up):
                message = (
                    f"not converging: merit down by less than {settings.give_up_decrease:.0%} in "
                    f"{give_up} iterations, residual rms {ms.residual_rms(ev.cost):.3g} noise std"
                )
                break
            walk.costs.append(ev.cost)
            # Exact stages judge the decrease over the last ``cost_window`` iterations (a crawl
            # of tiny monotone steps along a valley lowers the cost a little every time).
            span = 1 if penalty is not None else settings.cost_window
            costs = walk.costs
            if (
                cost_rtol > 0
                and len(costs) > span
                and 0 <= costs[-1 - span] - ev.cost <= span * cost_rtol * ev.cost
                and (penalty is not None or max_defect <= defect_tol)
            ):
                converged = True
                message = f"cost decrease below {cost_rtol:g} (relative)"
                if penalty is None:
                    message += f", largest continuity defect {max_defect:.2g} noise std"
                break
            asked = interrupt and penalty is None and len(costs) > span and max_defect <= defect_tol
            if asked and (stop := interrupt(ev, costs[-1 - span] - ev.cost)):
                converged, message = True, stop
                break
            if trial.step <= step_tol and trial.full_step and max_defect <= defect_tol:
                converged = True
                message = f"converged: parameter step {trial.step:.1e} <= {step_tol:.0e}"
                break
        if walk.best[0] < walk.merit(ev, state.nodes) and not converged:
            _, state.nodes, state.theta, ev = walk.best
            state.evaluation = ev
        return StageReport(
            name=stage,
            smoothing=smoothing,
            iterations=iterations,
            converged=converged,
            message=message,
            cost=ev.cost,
            max_defect=float(np.max(np.abs(ms.defects(ev, state.nodes, self.links)), initial=0)),
            wall_time_s=time.perf_counter() - start,
            at_bound=self._at_bound(state),
            substeps=ev.n_substeps,
            radius=walk.radius,
        )

    def _trial(self, walk: _Walk, state: SolverState, smoothing, iterations: int) -> _Trial:
        """One iteration's step: the Gauss-Newton step within the trust region and the
        bounds, the region (and the node damping) shrunk until the merit accepts a step or
        the region collapses. Raises the l1 penalty parameter where a step needs it."""
        ms, settings = self.ms, self.settings
        lo, hi = self.problem.theta_lower, self.problem.theta_upper
        ev = state.evaluation
        penalty = walk.penalty
        out = _Trial(current=walk.merit(ev, state.nodes))
        free = state.active.copy()
        index = np.flatnonzero(free)
        damping_used = None
        wall = None
        while walk.radius >= settings.min_radius and self.node_damping <= settings.max_node_damping:
            key = (self.node_damping, self.prox_scale)
            if damping_used != key:
                h_red, g_red, complete = self._linear_model(ev, state.nodes, free, penalty)
                damping_used = key
            out.overflowed = not (np.all(np.isfinite(h_red)) and np.all(np.isfinite(g_red)))
            if out.overflowed:
                break
            d, out.full_step = self._bounded_step(
                h_red, g_red, state.theta[index], lo[index], hi[index], walk.radius, wall
            )
            dnodes, change = complete(d)
            dtheta = np.zeros_like(state.theta)
            dtheta[index] = d
            theta_new = state.theta + dtheta
            nodes_new = state.nodes + dnodes
            if penalty is None:
                l1 = float(np.sum(np.abs(ms.defects(ev, state.nodes, self.links))))
                raised = _penalty_parameter(walk.mu, change, l1, settings.merit_rho)
                if raised > walk.mu:
                    walk.mu = raised
                    out.current = walk.merit(ev, state.nodes)
                    walk.best = (walk.merit(walk.best[3], walk.best[1]),) + walk.best[1:]
                # Cost along the step, defects linearly closed (exact continuity).
                walk.predicted = out.current - (ev.cost + change)
            else:
                walk.predicted = -change
            trial = self._evaluate(state, nodes_new, theta_new, smoothing, derivatives=False)
            if wall is None and trial.n_substeps[1] > ms.transcription.max_substeps:
                wall = StiffnessWall.at(ms, state.theta, index, smoothing)
                continue
            new = walk.merit(trial, nodes_new)
            current, predicted = out.current, walk.predicted
            ratio = (current - new) / predicted if predicted > 0 else -1.0
            if abs(predicted) <= 1e-9 * (abs(current) + 1.0) and new <= current:
                # At the optimum the predicted gain is rounding noise: no verdict.
                ratio = 0.5
            if not walk.monotone:
                ratio, ok = _watchdog_verdict(
                    ratio,
                    new,
                    current,
                    walk.best[0],
                    iterations <= settings.free_steps,
                    settings.watchdog_factor,
                )
            self._adapt_region(walk, ratio, new, float(np.linalg.norm(d)), index.size)
            if walk.monotone and penalty is None and not (np.isfinite(new) and ratio > 1e-4):
                # The defect-closing part of the step is not limited by the trust region
                # (it is not a parameter step): shorten the whole step instead.
                shortened = self._shortened(walk, state, dnodes, dtheta, current, smoothing)
                if shortened is not None:
                    trial, new, nodes_new, theta_new, alpha = shortened
                    ratio, d = 0.5, alpha * d
            if walk.monotone:
                ok = np.isfinite(new) and ratio > 1e-4
            if ok:
                out.accepted = True
                out.step = float(np.max(np.abs(d), initial=0.0))
                # The next iteration's linearization: the same integration (the same
                # velocity hint, so bitwise the same trajectory) with its sensitivities.
                trial = self._evaluate(state, nodes_new, theta_new, smoothing)
                out.nodes, out.theta, out.evaluation = nodes_new, theta_new, trial
                break
            out.full_step = False
        return out

    def _linear_model(self, ev: Evaluation, nodes, free: np.ndarray, penalty: float | None):
        """The reduced Gauss-Newton model at ``ev`` (exact continuity, or continuity as a
        ``penalty``): (H, g, complete), ``complete(d)`` the node steps and model cost change
        of a parameter step d. Sensitivities that overflow give non-finite H or g, the
        caller's verdict, not a numpy warning printed on the user's terminal."""
        with np.errstate(over="ignore", invalid="ignore"):
            linearized = (
                self._linearize(ev, nodes, free)
                if penalty is None
                else self._linearize_penalty(ev, nodes, free, penalty)
            )
            return self._with_prior(ev, free, linearized, exact=penalty is None)

    def step_from(self, state: SolverState, smoothing: tuple[float, float]) -> float:
        """The largest free-parameter change [log p] of the Gauss-Newton step from
        ``state`` (exact continuity, as a stage's first iteration computes it, within the
        largest trust region and the bounds); inf where the region or non-finite
        sensitivities cut it. ``run``'s step criterion (converged at ``step_tol``) applied
        to a point another solver reached."""
        self.node_damping = self.settings.node_damping
        self.set_smoothing(smoothing, self.settings.proximal_weight)
        self.links = self.ms.linked.copy()
        ev = self._evaluate(state, state.nodes, state.theta, smoothing)
        index = np.flatnonzero(state.active)
        h_red, g_red, _ = self._linear_model(ev, state.nodes, state.active.copy(), None)
        if not (np.all(np.isfinite(h_red)) and np.all(np.isfinite(g_red))):
            return math.inf
        lo, hi = self.problem.theta_lower, self.problem.theta_upper
        d, full_step = self._bounded_step(
            h_red, g_red, state.theta[index], lo[index], hi[index], self.settings.max_radius
        )
        return float(np.max(np.abs(d), initial=0.0)) if full_step else math.inf

    def _bounded_step(
        self, h_red, g_red, theta_f, lower, upper, radius: float, wall: StiffnessWall | None = None
    ):
        """(step in the free log-parameters, whether the trust region left it whole):
        ``trust_region.bounded_step`` within the bounds and the stiffness wall (where a
        trial was refused for stiffness), parameters at a bound whose step points outward
        held.

        Parameters the data do not determine at all (textbook relative std above
        ``settings.sloppy_std``) are not moved: along such directions Gauss-Newton steps are
        arbitrary and can take the model somewhere stiff and ill-conditioned. The
        identifiability step later holds them at their initial value."""
        movable = (
            _determined(h_red, self.settings.sloppy_std)
            if self.freeze_sloppy
            else np.ones(len(theta_f), dtype=bool)
        )
        half_space = None if wall is None else (wall.normal, wall.margin)
        return bounded_step(h_red, g_red, theta_f, lower, upper, radius, movable, half_space)

    def _adapt_region(self, walk: _Walk, ratio: float, new: float, length: float, n_free: int):
        """The trust region and the node damping after a step of ``length`` whose merit
        ratio (actual / predicted decrease) is ``ratio``."""
        settings = self.settings
        if not np.isfinite(new) or ratio < 0.25:
            if n_free:
                # (Node-only stages: nothing for the region to limit; the node damping
                # below does the shortening.)
                shrunk = 0.25 * max(length, settings.min_radius)
                walk.radius = shrunk if np.isfinite(new) else 0.1 * walk.radius
            self.node_damping *= 10.0
            self.prox_scale = min(self.prox_scale * 10.0, settings.max_prox_scale)
        elif ratio > 0.75:
            self.node_damping = max(settings.node_damping, self.node_damping / 10.0)
            self.prox_scale = max(self.prox_scale / 4.0, settings.min_prox_scale)
            if length >= 0.9 * walk.radius:
                walk.radius = min(2 * walk.radius, settings.max_radius)
        if not walk.monotone:
            # The watchdog guards the exact stages; the trust region only keeps single
            # steps sane, so it must not shrink to nothing over noise-level merit changes
            # near the optimum.
            walk.radius = max(walk.radius, settings.watchdog_min_radius)

    def _shortened(self, walk: _Walk, state: SolverState, dnodes, dtheta, current, smoothing):
        """The whole step (nodes and parameters) shortened to 1/2, 1/4, 1/8 until the merit
        falls by a share of what the model predicts: (evaluation, merit, nodes, theta,
        factor), or None."""
        rjd, jdjd = self.model_terms
        cost = state.evaluation.cost
        penalty_now = current - cost  # mu |defects|_1 in the merit
        for alpha in (0.5, 0.25, 0.125):
            nodes_a = state.nodes + alpha * dnodes
            theta_a = state.theta + alpha * dtheta
            trial_a = self._evaluate(state, nodes_a, theta_a, smoothing, derivatives=False)
            new_a = walk.merit(trial_a, nodes_a)
            model = cost + alpha * rjd + 0.5 * alpha**2 * jdjd
            predicted_a = current - (model + (1 - alpha) * penalty_now)
            if np.isfinite(new_a) and predicted_a > 0 and ((current - new_a) / predicted_a > 1e-4):
                return trial_a, new_a, nodes_a, theta_a, alpha
        return None

    def _accept(self, walk: _Walk, state: SolverState, trial: _Trial, iterations: int):
        """Move to the accepted step and keep the watchdog's books (returning to the best
        iterate, with a smaller region, once it has not improved for a while)."""
        ms, settings = self.ms, self.settings
        state.nodes, state.theta, ev = trial.nodes, trial.theta, trial.evaluation
        state.evaluation = ev
        state.velocity_hint = ev.states[:, :, ms.nq :]
        value = walk.merit(ev, state.nodes)
        if (not walk.monotone and iterations <= settings.free_steps) or value < walk.best[0]:
            walk.best = (value, state.nodes, state.theta, ev)
            walk.since_best = 0
        else:
            walk.since_best += 1
        if walk.since_best >= settings.watchdog_patience:
            _, state.nodes, state.theta, ev = walk.best
            state.evaluation = ev
            state.velocity_hint = ev.states[:, :, ms.nq :]
            walk.radius = max(0.1 * trial.step, settings.watchdog_min_radius)
            walk.reverts += 1
            # A second return to the same best point would start a cycle: from then on the
            # stage is a monotone trust-region method.
            walk.monotone = walk.reverts >= settings.watchdog_reverts
            walk.since_best = 0
            trial.full_step = False

    def _stalled(self, walk: _Walk, state, smoothing, defect_tol, stall_defect_tol, current):
        """No step decreases the merit: (converged, message, evaluation). That is convergence
        if the model predicted (almost) nothing, or if all that is left are continuity
        defects below the noise (typically a velocity at rest, where closing is nonlinear
        in v_s)."""
        ms = self.ms
        ev = state.evaluation
        max_defect = float(np.max(np.abs(ms.defects(ev, state.nodes, self.links)), initial=0))
        at_noise_level = ms.residual_rms(ev.cost) <= self.settings.stall_noise_ratio
        at_tolerance = abs(walk.predicted) <= 1e-10 * max(ev.cost, 1.0) and max_defect <= defect_tol
        exact = walk.penalty is None
        converged = at_tolerance or (exact and max_defect <= stall_defect_tol and at_noise_level)
        message = (
            "converged: no further decrease possible (largest continuity defect "
            f"{max_defect:.2g} noise std)"
            if converged
            else "stalled: no step decreases the cost"
        )
        # Defects above the tolerance (a stall accepted below ``stall_defect_tol``, or not
        # accepted) are closed by simulation where that fits as well: a real trajectory, not
        # one continuous only to within the noise.
        if not at_tolerance and exact:
            closed = self._close_by_simulation(state, ev, smoothing, current)
            if closed is not None:
                ev = closed
                max_defect = float(
                    np.max(np.abs(ms.defects(ev, state.nodes, self.links)), initial=0)
                )
                if max_defect <= defect_tol:
                    converged = True
                    message = (
                        "converged: no step decreases the cost; continuity closed by "
                        "simulating from the initial states (cost within "
                        f"{self.settings.close_cost_tol:g} of the multiple-shooting optimum)"
                    )
        return converged, message, ev

    def _gives_up(self, walk: _Walk, ev: Evaluation, give_up: int) -> bool:
        """A fast path far from the noise level whose best merit has fallen by less than
        ``settings.give_up_decrease`` over the last ``give_up`` iterations."""
        settings = self.settings
        history = walk.best_history
        return (
            len(history) > give_up
            and walk.best[0] > (1 - settings.give_up_decrease) * history[-1 - give_up]
            and self.ms.residual_rms(ev.cost) > settings.give_up_noise_ratio
        )

    def _report_progress(self, stage, smoothing, iteration, ev, step, max_defect, walk):
        """One iteration to the progress sink, if any."""
        if self.progress is None:
            return
        self.progress(
            FitProgress(
                stage=f"{stage} v_s={smoothing[0]:g},{smoothing[1]:g}",
                iteration=iteration,
                cost=ev.cost,
                step=step,
                defect=max_defect,
                message=f"radius={walk.radius:.1e} substeps={ev.n_substeps} "
                f"stiff_windows={ev.n_stiff_windows}",
            )
        )

    def _at_bound(self, state: SolverState) -> list[int]:
        """Indices of the active free parameters at a bound (within ``AT_BOUND``)."""
        lo, hi = self.problem.theta_lower, self.problem.theta_upper
        return [
            int(i)
            for i in np.flatnonzero(state.active)
            if state.theta[i] <= lo[i] + AT_BOUND or state.theta[i] >= hi[i] - AT_BOUND
        ]
