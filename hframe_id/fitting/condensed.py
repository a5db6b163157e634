"""The condensed Gauss-Newton model of the lifted multiple-shooting problem.

Exact continuity: the conditions x_end(node_i, theta) = node_{i+1} are linearised and
condensed (Bock): node steps become affine in each experiment's first node step and the
parameter step, ds_{i+1} = d_i + A_i ds_i + B_i dtheta, so each iteration solves a dense
system of n_x * experiments + n_free unknowns (``_linearize``). Penalty: continuity as
weighted residuals, block-tridiagonal normal equations (``_linearize_penalty``). At a
continuous point the condensed Jacobian is the single-shooting one that the statistics read
(``condensed_jacobian``), whichever solver found the point.
"""

from __future__ import annotations

import numpy as np

from hframe_id.fitting.gauss_newton_settings import GaussNewtonSettings
from hframe_id.fitting.shooting import Evaluation, MultipleShooting
from hframe_id.fitting.statistics import Block
from hframe_id.fitting.substep_plan import coordinate_smoothing

#: Floor of the Marquardt scaling, relative to the largest diagonal entry of the block.
DIAG_FLOOR = 1e-9


def _damped(h: np.ndarray, lam: float) -> np.ndarray:
    """H + lam * diag(max(diag H, floor)) for a stack of square matrices (..., n, n)."""
    diag = np.diagonal(h, axis1=-2, axis2=-1)
    floor = DIAG_FLOOR * np.max(diag, axis=-1, keepdims=True) + 1e-300
    d = np.maximum(diag, floor)
    out = h.copy()
    idx = np.arange(h.shape[-1])
    out[..., idx, idx] += np.asarray(lam)[..., None] * d
    return out


class CondensedModel:
    """The linearisations of one transcription's lifted problem, with the damping and
    proximal weights an iteration adapts."""

    def __init__(self, shooting: MultipleShooting):
        self.ms = shooting
        self.problem = shooting.problem
        self.links = shooting.linked.copy()
        self.prox_unit = np.zeros(shooting.nx)
        self.prox_scale = 1.0
        self.node_damping = GaussNewtonSettings.node_damping

    def set_smoothing(self, smoothing, weight: float = GaussNewtonSettings.proximal_weight):
        """Proximal weight on node velocity steps: a step of one smoothing velocity costs as
        much as one noise-sized residual. Near rest the dynamics change on that scale (the
        Coulomb law turns within a few v_s), and the speed at rest is nearly collinear with
        the position, so without it Gauss-Newton takes long, useless velocity steps.
        ``weight``: noise-sized residuals per smoothing velocity of step (0: none)."""
        vs = coordinate_smoothing(self.ms.model, smoothing)
        self.prox_unit = np.concatenate([np.zeros(self.ms.nq), weight / vs**2])
        self.prox_scale = 1.0

    @property
    def prox(self) -> np.ndarray:
        """The proximal weights in use: ``set_smoothing``'s unit times the adapted scale."""
        return self.prox_unit * self.prox_scale

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
        # a record's first node at rest steps only within its projector's range.
        damping = self.node_damping
        h_ss_d = _damped(h_ss, damping) + np.diag(self.prox)
        projector = self.ms.node_projector[np.flatnonzero(np.r_[True, ~links])]
        rows = _restrict(h_ss_d, h_sp, g_s, projector)
        k = np.linalg.solve(h_ss_d, np.concatenate([h_sp, g_s[:, :, None]], axis=2))
        k[rows] = projector[rows] @ k[rows]
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
        n_nuisance = ms.n_nuisance
        full = np.zeros((w, m, ny, n_nuisance + nf))
        column = 0
        for e, basis in enumerate(ms.initial_state_bases):
            idx = ms.window_experiment == e
            n = basis.shape[1]
            full[idx, :, :, column : column + n] = jc[idx][..., :nx] @ basis
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
                        sigma=float(self.problem.recording_std[e, j]),
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
        # A record's first node at rest steps only within its projector's range.
        projector = ms.node_projector
        rows = _restrict(diag_d, cross, grad, projector)
        upper[rows] = projector[rows] @ upper[rows]
        after = rows[rows > 0]
        upper[after - 1] = upper[after - 1] @ projector[after]
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
        x[rows] = projector[rows] @ x[rows]  # (``_restrict``)
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


def _restrict(
    blocks: np.ndarray, coupling: np.ndarray, gradient: np.ndarray, projector: np.ndarray
) -> np.ndarray:
    """Confines S node steps d to the ranges of their orthogonal ``projector``s (S, n, n) in
    the systems ``blocks`` (S, n, n) d = -[``coupling`` (S, n, k) dtheta + ``gradient``
    (S, n)]: blocks P H P + h (I - P), coupling P C, gradient P g, so d = P d, with h the
    block's largest diagonal entry (with 1 in place of h, rounding of P H P at eps h, 1e4 in
    a one-axis block, made the system singular). In place, and only where P is not the
    identity (elsewhere the systems are left bit for bit as they were: a fit with no record
    at rest is the same computation as before the projectors). Returns the indices of the
    restricted steps. (Rounding leaves (I - P) d at eps |d|: callers project their solution
    again at these indices.)"""
    rows = np.flatnonzero(np.any(projector != np.eye(projector.shape[-1]), axis=(1, 2)))
    p = projector[rows]
    b = blocks[rows]
    scale = np.max(np.abs(np.diagonal(b, axis1=1, axis2=2)), axis=1)[:, None, None]
    blocks[rows] = p @ b @ p + scale * (np.eye(blocks.shape[-1]) - p)
    coupling[rows] = p @ coupling[rows]
    gradient[rows] = (p @ gradient[rows][:, :, None])[:, :, 0]
    return rows
