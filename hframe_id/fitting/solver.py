"""Gauss-Newton (Levenberg-Marquardt) on the lifted multiple-shooting problem.

One kind of stage, ``continuity``, on ``MultipleShooting.evaluate``, in two forms:

- exact: the continuity conditions x_end(node_i, theta) = node_{i+1} are linearised
  and condensed (Bock): node steps become affine in each experiment's first node step and
  the parameter step, ds_{i+1} = d_i + A_i ds_i + B_i dtheta, so each iteration solves a
  dense system of n_x * experiments + n_free unknowns. The nonlinear defects close as the
  iteration converges; a watchdog on the merit globalises the step.
- penalty: continuity as weighted residuals (block-tridiagonal normal equations, monotone
  trust region), a fallback that takes a poor start into the exact form's basin.

Parameters stay within their bounds by projection: a parameter at a bound whose step points
outward is held for that iteration.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hframe_id.fitting.options import FitProgress
from hframe_id.fitting.shooting import Evaluation, MultipleShooting
from hframe_id.fitting.statistics import Block

#: Trust region on the log-parameters (2-norm): start, largest, smallest before giving up.
MAX_RADIUS = 4.0
MIN_RADIUS = 1e-9
#: Marquardt damping of the node blocks (relative to their diagonal): keeps the solve
#: regular where a window's data do not determine its node state (e.g. speed at rest).
NODE_DAMPING = 1e-6
MAX_NODE_DAMPING = 1e8
#: Proximal weight on node velocity steps (continuity stages), see ``set_smoothing``.
PROX_WEIGHT = 1.0
#: The proximal weight adapts like a Levenberg-Marquardt damping within these factors.
MIN_PROX_SCALE = 1e-3
MAX_PROX_SCALE = 1e4
#: Watchdog of the continuity stages.
WATCHDOG_FACTOR = 10.0
WATCHDOG_PATIENCE = 4
WATCHDOG_MIN_RADIUS = 1e-2
WATCHDOG_REVERTS = 2
#: A stalled exact stage is accepted as converged if simulating from the initial states (exact
#: continuity) costs at most this much more than the lifted iterate (chi^2 / 2 units).
CLOSE_COST_TOL = 1.0
#: ... and so is a stall with every continuity defect below this (noise std units).
STALL_DEFECT_TOL = 2.0
#: ... provided the fit is at the noise level (residual rms at most this many noise std):
#: a stall far from a good fit is a failure, whatever the defects.
STALL_NOISE_RATIO = 1.5
#: Continuity stages accept their first steps unconditionally: they close the defects left
#: by the previous stage, which raises the cost (and the merit) before it falls.
FREE_STEPS = 2
#: Fast paths (``give_up`` set) stop when the best merit has not fallen by GIVE_UP_DECREASE
#: (relative) over ``give_up`` iterations while the residual rms is above GIVE_UP_NOISE_RATIO
#: noise std: far from the data the exact stage can hover for many iterations where its
#: penalty fallback fits in a fraction of the time (docs/fitting.md, "The stages", 2).
GIVE_UP_DECREASE = 0.2
GIVE_UP_NOISE_RATIO = 10.0
#: Iterations over which an exact stage with ``cost_rtol`` judges the cost decrease.
COST_WINDOW = 10
#: Share of the removed l1 penalty a full exact-stage step must predict as merit decrease.
MERIT_RHO = 0.1
#: Textbook relative std (of log p) above which a parameter is not moved in an iteration.
SLOPPY_STD = 0.5
#: Floor of the Marquardt scaling, relative to the largest diagonal entry of the block.
DIAG_FLOOR = 1e-9


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


def _damped(h: np.ndarray, lam: float) -> np.ndarray:
    """H + lam * diag(max(diag H, floor)) for a stack of square matrices (..., n, n)."""
    diag = np.diagonal(h, axis1=-2, axis2=-1)
    floor = DIAG_FLOOR * np.max(diag, axis=-1, keepdims=True) + 1e-300
    d = np.maximum(diag, floor)
    out = h.copy()
    idx = np.arange(h.shape[-1])
    out[..., idx, idx] += np.asarray(lam)[..., None] * d
    return out


def _trust_region_step(h: np.ndarray, g: np.ndarray, radius: float) -> tuple[np.ndarray, bool]:
    """argmin g.d + d.H.d / 2 subject to |d|_2 <= radius (More-Sorensen, H = V E V^T >= 0).

    Returns the step and whether it is the full Gauss-Newton step (region inactive).
    """
    if g.size == 0:
        return np.zeros(0), True
    e, v = np.linalg.eigh(h)
    e = np.maximum(e, 1e-14 * max(float(e[-1]), 1e-300))
    gv = v.T @ g

    def step(mu: float) -> np.ndarray:
        return -v @ (gv / (e + mu))

    full = step(0.0)
    if np.linalg.norm(full) <= radius:
        return full, True
    # |step(mu)| falls with mu and is <= |g| / mu: bisect log(mu) in (|g| / r * 1e-14, |g| / r].
    hi = float(np.linalg.norm(g)) / radius
    lo = hi * 1e-14
    for _ in range(200):
        mid = math.sqrt(lo * hi)
        if np.linalg.norm(step(mid)) > radius:
            lo = mid
        else:
            hi = mid
        if hi <= lo * (1 + 1e-6):
            break
    return step(hi), False


def _penalty_parameter(mu: float, change: float, l1: float) -> float:
    """The l1 penalty parameter for a step that closes the linearised defects.

    The step changes the model cost by ``change`` (chi^2 / 2 units) and removes the defects
    ``l1`` = |defects|_1 (noise units). It must predict a merit decrease of at least
    ``MERIT_RHO`` times the penalty removed (Nocedal & Wright, eq. 18.36): mu is raised to
    ``change / ((1 - MERIT_RHO) l1)`` where it is smaller, and never lowered.
    """
    if l1 <= 0 or change <= (1 - MERIT_RHO) * mu * l1:
        return mu
    return change / ((1 - MERIT_RHO) * l1)


def _determined(h_red: np.ndarray) -> np.ndarray:
    """Parameters whose textbook relative std (from the reduced information, residuals in
    noise units) is at most SLOPPY_STD."""
    if h_red.size == 0:
        return np.ones(0, dtype=bool)
    d = np.sqrt(np.maximum(np.diag(h_red), 1e-300))
    cov = np.linalg.pinv(h_red / np.outer(d, d), rcond=1e-12, hermitian=True) / np.outer(d, d)
    return np.sqrt(np.maximum(np.diag(cov), 0.0)) <= SLOPPY_STD


class GaussNewton:
    """Iterates the stages of the lifted problem."""

    def __init__(self, shooting: MultipleShooting, progress=None, freeze_sloppy: bool = False):
        self.ms = shooting
        self.problem = shooting.problem
        self.progress = progress
        self.evaluations = 0
        self.links = shooting.linked.copy()
        self.prox_unit = np.zeros(shooting.nx)
        self.prox_scale = 1.0
        self.node_damping = NODE_DAMPING
        #: Hold undetermined parameters still (final stages, where the iterate is near an
        #: optimum; far from it a parameter can look undetermined only transiently).
        self.freeze_sloppy = freeze_sloppy

    def set_smoothing(self, smoothing, proximal: bool = True):
        """Proximal weight on node velocity steps: a step of one smoothing velocity costs as
        much as one noise-sized residual. Near rest the dynamics change on that scale (the
        Coulomb law turns within a few v_s), and the speed at rest is nearly collinear with
        the position, so without it Gauss-Newton takes long, useless velocity steps."""
        vs = np.array(
            [smoothing[0] if c.unit == "m" else smoothing[1] for c in self.ms.model.coordinates]
        )
        weight = PROX_WEIGHT if proximal else 0.0
        self.prox_unit = np.concatenate([np.zeros(self.ms.nq), weight / vs**2])
        self.prox_scale = 1.0

    @property
    def prox(self) -> np.ndarray:
        """The proximal weights in use: ``set_smoothing``'s unit times the adapted scale."""
        return self.prox_unit * self.prox_scale

    def rescale_channels(self, ev: Evaluation, factors: np.ndarray) -> None:
        """Multiply each output channel's weight by ``factors`` (n_y,): the transcription's
        weights (a new array: transcriptions sharing the old one keep it) and, in place,
        ``ev``'s residuals and their Jacobians (the same samples under the new weights)."""
        self.ms.weight = self.ms.weight * factors
        ev.residual *= factors
        if ev.jac_node is not None:
            ev.jac_node *= factors[:, None]
            ev.jac_theta *= factors[:, None]

    def _evaluate(self, state: SolverState, nodes, theta, smoothing) -> Evaluation:
        self.evaluations += 1
        return self.ms.evaluate(nodes, theta, smoothing, velocity_hint=state.velocity_hint)

    # ------------------------------------------------------------------ continuity stage
    def _linearize(self, ev: Evaluation, nodes, free: np.ndarray):
        """Condensed Gauss-Newton model over chains of linked windows (segments).

        Returns the reduced normal equations in the free log-parameters (every segment's
        first-node step eliminated) and ``complete(dtheta) -> (dnodes, r.Jd, |Jd|^2)``.
        """
        links = self.links
        w, m, ny, nx = ev.jac_node.shape
        nf = int(free.sum())
        segment = np.concatenate([[0], np.cumsum(~links)])
        n_seg = int(segment[-1]) + 1
        r_all = ev.residual.reshape(w, m * ny)
        js_all = ev.jac_node.reshape(w, m * ny, nx)
        jp_all = ev.jac_theta.reshape(w, m * ny, -1)[:, :, free]
        b_all = ev.b_end[:, :, free]
        defect = ev.x_end[:-1] - nodes[1:]
        offsets = np.zeros((w, nx))
        gains = np.zeros((w, nx, nx + nf))
        a = np.zeros(nx)
        gmat = np.hstack([np.eye(nx), np.zeros((nx, nf))])
        for i in range(w):
            if i > 0 and not links[i - 1]:
                a = np.zeros(nx)
                gmat = np.hstack([np.eye(nx), np.zeros((nx, nf))])
            offsets[i] = a
            gains[i] = gmat
            if i + 1 < w and links[i]:
                a = ev.a_end[i] @ a + defect[i]
                gmat = ev.a_end[i] @ gmat
                gmat[:, nx:] += b_all[i]
        # Batched BLAS products (einsum does not use BLAS: 3x slower here).
        jc = js_all @ gains
        jc[:, :, nx:] += jp_all
        rc = r_all + (js_all @ offsets[:, :, None])[:, :, 0]
        # Per segment: node block, coupling to theta; theta block summed.
        jc_t = jc.transpose(0, 2, 1)
        he = jc_t @ jc
        ge = (jc_t @ rc[:, :, None])[:, :, 0]
        h_ss = np.zeros((n_seg, nx, nx))
        h_sp = np.zeros((n_seg, nx, nf))
        g_s = np.zeros((n_seg, nx))
        np.add.at(h_ss, segment, he[:, :nx, :nx])
        np.add.at(h_sp, segment, he[:, :nx, nx:])
        np.add.at(g_s, segment, ge[:, :nx])
        h_pp = he[:, nx:, nx:].sum(axis=0)
        g_p = ge[:, nx:].sum(axis=0)
        # Eliminate the segments' first-node steps (block diagonal) by a Schur complement;
        # known entries (a record's initial velocities at rest) take no step.
        damping = self.node_damping
        h_ss_d = _damped(h_ss, damping) + np.diag(self.prox)
        _pin(h_ss_d, h_sp, g_s, self.ms.fixed_node[np.flatnonzero(np.r_[True, ~links])])
        k = np.linalg.solve(h_ss_d, np.concatenate([h_sp, g_s[:, :, None]], axis=2))
        k_sp, k_g = k[:, :, :-1], k[:, :, -1]
        h_red = h_pp - np.einsum("sij,sik->jk", h_sp, k_sp)
        g_red = g_p - np.einsum("sij,si->j", h_sp, k_g)

        def complete(dtheta_free):
            # First-node steps for this parameter step, then the linearised continuity.
            ds0 = -(k_g + np.einsum("sij,j->si", k_sp, dtheta_free))
            ze = np.concatenate([ds0[segment], np.broadcast_to(dtheta_free, (w, nf))], axis=1)
            dnodes = offsets + np.einsum("wij,wj->wi", gains, ze)
            jd_theta = np.einsum("wri,i->wr", jp_all, dtheta_free)
            jd = np.einsum("wri,wi->wr", js_all, dnodes) + jd_theta
            # Change of the cost along the step to second order; the defects close (linearly).
            self.model_terms = (float(np.sum(r_all * jd)), float(np.sum(jd * jd)))
            return dnodes, float(np.sum(r_all * jd) + 0.5 * np.sum(jd * jd))

        return h_red, g_red, complete

    def _with_prior(self, ev: Evaluation, free: np.ndarray, linearized, exact: bool):
        """The reduced model ``linearized`` = (h, g, complete) of a linearisation with the
        free parameters' prior residuals w theta added (``FitProblem.prior_weight``):
        h + diag(w^2), g + w r, and their change along a step."""
        h_red, g_red, complete = linearized
        w = self.problem.prior_weight[free]
        if not np.any(w):
            return linearized
        r = ev.prior_residual[free]

        def complete_with_prior(dtheta_free):
            dnodes, change = complete(dtheta_free)
            wd = w * dtheta_free
            linear, quadratic = float(r @ wd), float(wd @ wd)
            if exact:
                rjd, jdjd = self.model_terms
                self.model_terms = (rjd + linear, jdjd + quadratic)
            return dnodes, change + linear + 0.5 * quadratic

        return h_red + np.diag(w**2), g_red + w * r, complete_with_prior

    def condensed_jacobian(self, ev: Evaluation, nodes: np.ndarray, free: np.ndarray):
        """The single-shooting Jacobian at a continuous solution, from the window
        sensitivities chained along each experiment.

        Returns (J, r, blocks): J (n_valid, ``ms.n_nuisance`` + n_free) with the
        initial-state columns of each experiment whose initial state is estimated first, r
        the weighted residuals, and blocks
        (label "experiment:channel", row indices in time order) for the HAC estimator; a
        prior (``FitProblem.prior_weight``) adds a row and a block "prior:name" at the end.
        """
        ms = self.ms
        w, m, ny, nx = ev.jac_node.shape
        nf = int(free.sum())
        jp_all = ev.jac_theta[..., free]
        b_all = ev.b_end[:, :, free]
        gains = np.zeros((w, nx, nx + nf))
        gmat = np.hstack([np.eye(nx), np.zeros((nx, nf))])
        for i in range(w):
            if i > 0 and not ms.linked[i - 1]:
                gmat = np.hstack([np.eye(nx), np.zeros((nx, nf))])
            gains[i] = gmat
            if i + 1 < w and ms.linked[i]:
                gmat = ev.a_end[i] @ gmat
                gmat[:, nx:] += b_all[i]
        jc = np.einsum("wkji,wil->wkjl", ev.jac_node, gains)
        jc[..., nx:] += jp_all
        estimated = ms.estimated_initial_states
        n_nuisance = ms.n_nuisance
        full = np.zeros((w, m, ny, n_nuisance + nf))
        column = 0
        for e, entries in enumerate(estimated):
            idx = ms.window_experiment == e
            n = int(entries.sum())
            full[idx, :, :, column : column + n] = jc[idx][..., :nx][..., entries]
            column += n
        full[..., n_nuisance:] = jc[..., nx:]
        valid = ms.weight > 0
        order = np.arange(w * m * ny).reshape(w, m, ny)
        rows = order[valid]
        position = np.full(w * m * ny, -1)
        position[rows] = np.arange(rows.size)
        blocks = []
        names = self.problem.output_names
        measured = ms.measured[valid]
        for e, exp in enumerate(self.problem.experiments):
            idx = np.flatnonzero(ms.window_experiment == e)
            for j, name in enumerate(names):
                sel = order[idx, :, j].ravel()
                sel = position[sel]
                rows = sel[sel >= 0]
                blocks.append(
                    Block(
                        label=f"{exp.name}:{name}",
                        rows=rows,
                        sigma=float(self.problem.channel_std[j]),
                        quantization_step=float(self.problem.quantization[j]),
                        measured=measured[rows],
                    )
                )
        jac, residual = full[valid], ev.residual[valid]
        # The priors (``FitProblem.prior_weight``) are rows of their own: w on their
        # parameter's column, Gaussian with unit std in the noise-model bootstrap.
        w = self.problem.prior_weight[free]
        prior = np.flatnonzero(w)
        if not prior.size:
            return jac, residual, blocks
        rows = np.zeros((prior.size, jac.shape[1]))
        rows[np.arange(prior.size), n_nuisance + prior] = w[prior]
        free_names = np.array(self.problem.free_names)[free]
        for i, k in enumerate(prior):
            blocks.append(
                Block(
                    label=f"prior:{free_names[k]}",
                    rows=np.array([jac.shape[0] + i]),
                    sigma=1.0,
                    quantization_step=0.0,
                    measured=np.zeros(1),
                )
            )
        return np.vstack([jac, rows]), np.append(residual, ev.prior_residual[free][prior]), blocks

    def _linearize_penalty(self, ev: Evaluation, nodes, free: np.ndarray, weight: float):
        """Gauss-Newton model with continuity as weighted residuals (defects in noise units).

        The node steps are coupled only to their neighbours, so the normal equations are
        block tridiagonal in the nodes (plus the parameter arrow): a block Thomas sweep
        eliminates the nodes, leaving the reduced system in the free log-parameters.
        Returns it and ``complete(dtheta) -> (dnodes, model change)``.
        """
        ms = self.ms
        links = self.links
        w, m, ny, nx = ev.jac_node.shape
        scale = ms.defect_scale
        r = ev.residual.reshape(w, m * ny)
        js = ev.jac_node.reshape(w, m * ny, nx)
        jp = ev.jac_theta.reshape(w, m * ny, -1)[:, :, free]
        a = ev.a_end / scale[None, :, None]  # D^-1 A
        b = ev.b_end[:, :, free] / scale[None, :, None]  # D^-1 B
        d = np.zeros((w, nx))
        d[:-1] = (ev.x_end[:-1] - nodes[1:]) / scale
        link = np.zeros(w, dtype=bool)
        link[:-1] = links
        d[~link] = 0.0
        mu = weight * link.astype(float)
        inv = 1.0 / scale
        # Continuity residual of link i: c_i = d_i + a_i ds_i + b_i dtheta - inv * ds_{i+1}.
        diag = np.einsum("wri,wrj->wij", js, js) + mu[:, None, None] * np.einsum(
            "wki,wkj->wij", a, a
        )
        diag[1:] += (mu[:-1, None, None] * np.diag(inv**2)[None]).astype(float)
        upper = -mu[:, None, None] * a.transpose(0, 2, 1) * inv[None, None, :]  # (i, i+1)
        cross = np.einsum("wri,wrj->wij", js, jp) + mu[:, None, None] * np.einsum(
            "wki,wkj->wij", a, b
        )
        cross[1:] -= mu[:-1, None, None] * inv[None, :, None] * b[:-1]
        grad = np.einsum("wri,wr->wi", js, r) + mu[:, None] * np.einsum("wki,wk->wi", a, d)
        grad[1:] -= mu[:-1, None] * inv[None, :] * d[:-1]
        h_pp = np.einsum("wri,wrj->ij", jp, jp) + np.einsum("w,wki,wkj->ij", mu, b, b)
        g_p = np.einsum("wri,wr->i", jp, r) + np.einsum("w,wki,wk->i", mu, b, d)
        diag_d = _damped(diag, self.node_damping) + np.diag(self.prox)[None]
        # Known node entries (a record's initial velocities at rest) take no step.
        fixed = ms.fixed_node
        _pin(diag_d, cross, grad, fixed)
        upper[np.broadcast_to(fixed[:, :, None], upper.shape)] = 0.0
        upper[:-1][np.broadcast_to(fixed[1:, None, :], upper[:-1].shape)] = 0.0
        # Block Thomas: solve H_ss X = [cross, grad] for all right-hand sides at once.
        rhs = np.concatenate([cross, grad[:, :, None]], axis=2)
        c_prime = np.empty((w, nx, nx))
        r_prime = np.empty_like(rhs)
        for i in range(w):
            denom = diag_d[i]
            rr = rhs[i]
            if i > 0:
                lower = upper[i - 1].T
                denom = denom - lower @ c_prime[i - 1]
                rr = rr - lower @ r_prime[i - 1]
            lu = np.linalg.solve(denom, np.hstack([upper[i], rr]))
            c_prime[i] = lu[:, :nx]
            r_prime[i] = lu[:, nx:]
        x = np.empty_like(rhs)
        x[-1] = r_prime[-1]
        for i in range(w - 2, -1, -1):
            x[i] = r_prime[i] - c_prime[i] @ x[i + 1]
        x_p, x_g = x[:, :, :-1], x[:, :, -1]
        h_red = h_pp - np.einsum("wij,wik->jk", cross, x_p)
        g_red = g_p - np.einsum("wij,wi->j", cross, x_g)

        def complete(dtheta_free):
            dnodes = -(x_g + np.einsum("wij,j->wi", x_p, dtheta_free))
            jd = np.einsum("wri,wi->wr", js, dnodes) + np.einsum("wri,i->wr", jp, dtheta_free)
            cd = np.einsum("wki,wi->wk", a, dnodes) + np.einsum("wki,i->wk", b, dtheta_free)
            cd[:-1] -= inv[None, :] * dnodes[1:]
            # Change of cost + weight/2 |d|^2 along the step, to second order.
            change = float(np.sum(r * jd) + 0.5 * np.sum(jd * jd))
            change += float(np.sum(mu[:, None] * (d * cd + 0.5 * cd * cd)))
            return dnodes, change

        return h_red, g_red, complete

    def _close_by_simulation(self, state: SolverState, ev: Evaluation, smoothing, merit_now):
        """At a stall with small defects left (typically velocities at rest, where closing
        them is nonlinear), replace the nodes by one simulation per experiment from its
        initial state. If that continuous trajectory fits as well as the lifted iterate
        (cost within ``CLOSE_COST_TOL``, in units of chi^2 / 2), it is the solution."""
        ms = self.ms
        known = np.zeros(ms.n_windows, dtype=bool)
        known[np.flatnonzero(np.r_[True, ~self.links])] = True
        nodes = ms.fill_nodes(state.nodes, known, state.theta, smoothing)
        trial = self._evaluate(state, nodes, state.theta, smoothing)
        if not np.isfinite(trial.cost) or trial.cost > merit_now + CLOSE_COST_TOL:
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
        stall_defect_tol: float = STALL_DEFECT_TOL,
        reweight: Callable[[Evaluation], np.ndarray | None] | None = None,
    ) -> StageReport:
        """Iterate one stage until converged; updates ``state`` in place.

        ``stage`` names the stage in progress reports. Exact continuity (``penalty`` None):
        nearly full Gauss-Newton steps under a watchdog (see the module docstring); with
        ``penalty``: continuity as weighted residuals, monotone trust region.

        Converged: the last step was a full Gauss-Newton step (trust region inactive) that
        changed no free parameter by more than ``step_tol`` (relative), and the continuity
        defects are below ``defect_tol`` (noise units). A stage may also stop once an
        iteration lowers the cost by less than ``cost_rtol`` (relative; exact stages: on
        average over ``COST_WINDOW`` iterations, with the defects below ``defect_tol``).
        With ``give_up``, a stage far from the noise level that stops making progress ends
        unconverged early (for fast paths that have a fallback). A stall at the noise level
        with every defect below ``stall_defect_tol`` is accepted too, unless a simulation from
        the initial states closes them as well (``_close_by_simulation``); where the noise
        levels are estimated from the residuals (model error) the caller passes
        ``defect_tol`` (no such acceptance): defects of 2 estimated std let a discontinuous
        trajectory follow data its model cannot.

        ``reweight`` (monotone stages): called at every accepted iterate with its evaluation;
        it returns factors (n_y,) for the channels' weights, or None to keep them. Re-weighted,
        the merit is another function: the best iterate and the cost history restart there.
        """
        start = time.perf_counter()
        ms = self.ms
        self.node_damping = NODE_DAMPING
        self.set_smoothing(smoothing, proximal=True)
        self.links = ms.linked.copy()
        lo, hi = self.problem.theta_lower, self.problem.theta_upper
        ev = self._evaluate(state, state.nodes, state.theta, smoothing)
        state.evaluation = ev
        state.velocity_hint = ev.states[:, :, ms.nq :]
        converged = False
        message = f"not converged in {max_iterations} iterations"
        iterations = 0

        # Exact stages: the l1 exact penalty cost + mu |defects|_1 (noise units), mu raised
        # so that every full step predicts a decrease (see ``_penalty_parameter``): unlike a
        # fixed quadratic penalty, whose minimiser leaves defects of the size of the
        # multipliers (hundreds of noise std when the model cannot follow the data), its
        # minimiser is the continuous trajectory. Penalty stages: the quadratic penalty.
        mu = [1.0]

        def merit(ev_, nodes_):
            defects = ms.defects(ev_, nodes_, self.links)
            if penalty is None:
                return ev_.cost + mu[0] * float(np.sum(np.abs(defects)))
            return ev_.cost + 0.5 * penalty * float(np.sum(defects**2))

        best = (merit(ev, state.nodes), state.nodes, state.theta, ev)
        best_history = []
        costs = [ev.cost]
        # Exact stages start with the watchdog; once it has had to step back, they continue
        # as a monotone trust-region method (so they cannot cycle).
        monotone = penalty is not None or not watchdog
        reverts = 0
        since_best = 0
        for iterations in range(1, max_iterations + 1):
            accepted = False
            full_step = False
            step = 0.0
            current = merit(ev, state.nodes)
            free = state.active.copy()
            index = np.flatnonzero(free)
            damping_used = None
            overflowed = False
            while radius >= MIN_RADIUS and self.node_damping <= MAX_NODE_DAMPING:
                key = (self.node_damping, self.prox_scale)
                if damping_used != key:
                    linearized = (
                        self._linearize(ev, state.nodes, free)
                        if penalty is None
                        else self._linearize_penalty(ev, state.nodes, free, penalty)
                    )
                    h_red, g_red, complete = self._with_prior(
                        ev, free, linearized, exact=penalty is None
                    )
                    damping_used = key
                overflowed = not (np.all(np.isfinite(h_red)) and np.all(np.isfinite(g_red)))
                if overflowed:
                    break
                # Parameters the data do not determine at all (textbook relative std above
                # SLOPPY_STD) are not moved: along such directions Gauss-Newton steps are
                # arbitrary and can take the model somewhere stiff and ill-conditioned. The
                # identifiability step later holds them at their initial value.
                sub = _determined(h_red) if self.freeze_sloppy else np.ones(len(index), dtype=bool)
                # Hold parameters at a bound whose step points outward, then clip.
                for _ in range(len(index) + 1):
                    d_sub, full_step = _trust_region_step(
                        h_red[np.ix_(sub, sub)], g_red[sub], radius
                    )
                    d = np.zeros(len(index))
                    d[sub] = d_sub
                    theta_f = state.theta[index]
                    out = sub & (
                        ((theta_f <= lo[index] + 1e-12) & (d < 0))
                        | ((theta_f >= hi[index] - 1e-12) & (d > 0))
                    )
                    if not out.any():
                        break
                    sub &= ~out
                d = np.clip(theta_f + d, lo[index], hi[index]) - theta_f
                dnodes, change = complete(d)
                dtheta = np.zeros_like(state.theta)
                dtheta[index] = d
                theta_new = state.theta + dtheta
                nodes_new = state.nodes + dnodes
                if penalty is None:
                    l1 = float(np.sum(np.abs(ms.defects(ev, state.nodes, self.links))))
                    raised = _penalty_parameter(mu[0], change, l1)
                    if raised > mu[0]:
                        mu[0] = raised
                        current = merit(ev, state.nodes)
                        best = (merit(best[3], best[1]),) + best[1:]
                    # Cost along the step, defects linearly closed (exact continuity).
                    predicted = current - (ev.cost + change)
                else:
                    predicted = -change
                trial = self._evaluate(state, nodes_new, theta_new, smoothing)
                new = merit(trial, nodes_new)
                ratio = (current - new) / predicted if predicted > 0 else -1.0
                if abs(predicted) <= 1e-9 * (abs(current) + 1.0) and new <= current:
                    # At the optimum the predicted gain is rounding noise: no verdict.
                    ratio = 0.5
                if not monotone and new <= current:
                    # Exact stages judge steps by the watchdog; shrink only on an increase.
                    ratio = max(ratio, 0.5)
                length = float(np.linalg.norm(d))
                if not np.isfinite(new) or ratio < 0.25:
                    if index.size:
                        # (Node-only stages: nothing for the region to limit; the node
                        # damping below does the shortening.)
                        radius = (
                            0.25 * max(length, MIN_RADIUS) if np.isfinite(new) else 0.1 * radius
                        )
                    self.node_damping *= 10.0
                    self.prox_scale = min(self.prox_scale * 10.0, MAX_PROX_SCALE)
                elif ratio > 0.75:
                    self.node_damping = max(NODE_DAMPING, self.node_damping / 10.0)
                    self.prox_scale = max(self.prox_scale / 4.0, MIN_PROX_SCALE)
                    if length >= 0.9 * radius:
                        radius = min(2 * radius, MAX_RADIUS)
                if not monotone:
                    # The watchdog guards the exact stages; the trust region only keeps
                    # single steps sane, so it must not shrink to nothing over noise-level
                    # merit changes near the optimum.
                    radius = max(radius, WATCHDOG_MIN_RADIUS)
                if monotone and penalty is None and not (np.isfinite(new) and ratio > 1e-4):
                    # The defect-closing part of the step is not limited by the trust region
                    # (it is not a parameter step): shorten the whole step instead.
                    rjd, jdjd = self.model_terms
                    penalty_now = current - ev.cost  # mu |defects|_1 in the merit
                    for alpha in (0.5, 0.25, 0.125):
                        nodes_a = state.nodes + alpha * dnodes
                        theta_a = state.theta + alpha * dtheta
                        trial_a = self._evaluate(state, nodes_a, theta_a, smoothing)
                        new_a = merit(trial_a, nodes_a)
                        model = ev.cost + alpha * rjd + 0.5 * alpha**2 * jdjd
                        predicted_a = current - (model + (1 - alpha) * penalty_now)
                        if (
                            np.isfinite(new_a)
                            and predicted_a > 0
                            and ((current - new_a) / predicted_a > 1e-4)
                        ):
                            trial, new, ratio = trial_a, new_a, 0.5
                            nodes_new, theta_new, d = nodes_a, theta_a, alpha * d
                            break
                if monotone:
                    ok = np.isfinite(new) and ratio > 1e-4
                elif iterations <= FREE_STEPS:
                    ok = bool(np.isfinite(new))  # closes the defects left by the last stage
                else:
                    ok = np.isfinite(new) and new < WATCHDOG_FACTOR * best[0]
                if ok:
                    accepted = True
                    step = float(np.max(np.abs(d), initial=0.0))
                    break
                full_step = False
            if accepted:
                state.nodes, state.theta, ev = nodes_new, theta_new, trial
                state.evaluation = ev
                state.velocity_hint = ev.states[:, :, ms.nq :]
                value = merit(ev, state.nodes)
                factors = None if reweight is None else reweight(ev)
                if factors is not None:
                    self.rescale_channels(ev, factors)
                    best = (merit(ev, state.nodes), state.nodes, state.theta, ev)
                    since_best = 0
                    best_history.clear()
                    costs.clear()
                elif not monotone and iterations <= FREE_STEPS:
                    best = (value, state.nodes, state.theta, ev)
                    since_best = 0
                elif value < best[0]:
                    best = (value, state.nodes, state.theta, ev)
                    since_best = 0
                else:
                    since_best += 1
                if since_best >= WATCHDOG_PATIENCE:
                    # The watchdog: back to the best iterate, with a smaller trust region.
                    _, state.nodes, state.theta, ev = best
                    state.evaluation = ev
                    state.velocity_hint = ev.states[:, :, ms.nq :]
                    radius = max(0.1 * step, WATCHDOG_MIN_RADIUS)
                    reverts += 1
                    # A second return to the same best point would start a cycle: from
                    # then on the stage is a monotone trust-region method.
                    monotone = reverts >= WATCHDOG_REVERTS
                    since_best = 0
                    full_step = False
            if overflowed:
                message = (
                    "stopped: the model's sensitivities overflow at these parameters (so stiff "
                    "or unstable there that no step can be computed)"
                )
                break
            max_defect = float(np.max(np.abs(ms.defects(ev, state.nodes, self.links)), initial=0))
            if self.progress is not None:
                self.progress(
                    FitProgress(
                        stage=f"{stage} v_s={smoothing[0]:g},{smoothing[1]:g}",
                        iteration=iterations,
                        cost=ev.cost,
                        step=step,
                        defect=max_defect,
                        message=f"radius={radius:.1e} substeps={ev.n_substeps} "
                        f"stiff_windows={ev.n_stiff_windows}",
                    )
                )
            if not accepted:
                # No step decreases the merit. That is convergence if the model predicted
                # (almost) nothing, or if all that is left are continuity defects below the
                # noise (typically a velocity at rest, where closing is nonlinear in v_s).
                at_noise_level = ms.residual_rms(ev.cost) <= STALL_NOISE_RATIO
                at_tolerance = (
                    abs(predicted) <= 1e-10 * max(ev.cost, 1.0) and max_defect <= defect_tol
                )
                converged = at_tolerance or (
                    penalty is None and max_defect <= stall_defect_tol and at_noise_level
                )
                message = (
                    "converged: no further decrease possible (largest continuity defect "
                    f"{max_defect:.2g} noise std)"
                    if converged
                    else "stalled: no step decreases the cost"
                )
                # Defects above the tolerance (a stall accepted below STALL_DEFECT_TOL, or
                # not accepted) are closed by simulation where that fits as well: a real
                # trajectory, not one continuous only to within the noise.
                if not at_tolerance and penalty is None:
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
                                f"{CLOSE_COST_TOL:g} of the multiple-shooting optimum)"
                            )
                break
            best_history.append(best[0])
            if (
                give_up is not None
                and len(best_history) > give_up
                and best[0] > (1 - GIVE_UP_DECREASE) * best_history[-1 - give_up]
                and ms.residual_rms(ev.cost) > GIVE_UP_NOISE_RATIO
            ):
                message = (
                    f"not converging: merit down by less than {GIVE_UP_DECREASE:.0%} in "
                    f"{give_up} iterations, residual rms {ms.residual_rms(ev.cost):.3g} noise std"
                )
                break
            costs.append(ev.cost)
            # Exact stages judge the decrease over the last COST_WINDOW iterations (a crawl
            # of tiny monotone steps along a valley lowers the cost a little every time).
            span = 1 if penalty is not None else COST_WINDOW
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
            if step <= step_tol and full_step and max_defect <= defect_tol:
                converged = True
                message = f"converged: parameter step {step:.1e} <= {step_tol:.0e}"
                break
        if best[0] < merit(ev, state.nodes) and not converged:
            _, state.nodes, state.theta, ev = best
            state.evaluation = ev
        at_bound = [
            int(i)
            for i in np.flatnonzero(state.active)
            if state.theta[i] <= lo[i] + 1e-9 or state.theta[i] >= hi[i] - 1e-9
        ]
        return StageReport(
            name=stage,
            smoothing=smoothing,
            iterations=iterations,
            converged=converged,
            message=message,
            cost=ev.cost,
            max_defect=float(np.max(np.abs(ms.defects(ev, state.nodes, self.links)), initial=0)),
            wall_time_s=time.perf_counter() - start,
            at_bound=at_bound,
            substeps=ev.n_substeps,
            radius=radius,
        )


def _pin(blocks: np.ndarray, coupling: np.ndarray, gradient: np.ndarray, fixed: np.ndarray) -> None:
    """Makes the ``fixed`` entries (S, n) of S node steps zero in the systems
    ``blocks`` (S, n, n) d = -[``coupling`` (S, n, k) dtheta + ``gradient`` (S, n)]: their rows
    and columns become those of the identity, their right-hand sides zero. In place."""
    rows = np.broadcast_to(fixed[:, :, None], blocks.shape)
    cols = np.broadcast_to(fixed[:, None, :], blocks.shape)
    blocks[rows | cols] = 0.0
    step, entry = np.nonzero(fixed)
    blocks[step, entry, entry] = 1.0
    coupling[fixed] = 0.0
    gradient[fixed] = 0.0
