"""CasADi's own NLP solvers (IPOPT, ``sqpmethod``) on the multiple-shooting problem.

The same problem as the Gauss-Newton solver (``fitting/solver.py``) solves, in the same
transcription (``MultipleShooting``: its windows, data layout, weights and substep choice),
handed to ``nlpsol`` as one NLP:

    min  1/2 sum r(z, theta)^2    s.t.  (x_end,i(z_i, theta) - z_{i+1} s) / s = 0  for linked
                                        windows i, i + 1 of one experiment,
                                        theta_lower <= theta <= theta_upper

r are the noise-weighted output residuals of the valid samples, z_i = node_i / s the node
states in units of the defect scale s (``MultipleShooting.defect_scale``: one noise std for
positions, that over one sample for speeds), so that residual, constraint and variable
scales are all noise-sized; theta the active free log-parameters. Variables are ordered
node by node, theta last (the constraint Jacobian is block bidiagonal plus a theta column
block). The Hessian of the Lagrangian is the Gauss-Newton Hessian J^T J of the residuals
(exact for the cost's curvature to first order in r, zero for the constraints' curvature),
as in CasADi's ``docs/examples/python/sysid.py``.

The expression graph is one ``kernel.window_function`` (a ``map`` over windows of a
``mapaccum`` over samples of the RK4 substep): nothing is unrolled over the record.
Every window is integrated with the stiff (at-rest) substep count of ``substep_plan``, as
the Gauss-Newton solver's final stage does (``MultipleShooting.uniform``); if the parameters move
to where that count is no longer stable, the NLP is rebuilt with the larger count and
solved again from its own solution.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from hframe_id.errors import OptionError
from hframe_id.fitting.kernel import compiled_state_substep, compiled_substep, window_function
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.fitting.substep_plan import stopped_message

#: NLP solvers of the installed CasADi that this module drives.
SOLVERS = ("ipopt", "sqpmethod")
#: QP solvers for ``sqpmethod``.
QP_SOLVERS = ("qpoases", "osqp", "qrqp")
#: Rebuilds with a larger substep count (parameters moving into stiffer dynamics) at most.
MAX_REBUILDS = 3


@dataclass(frozen=True)
class NlpSettings:
    """How to solve the NLP.

    Attributes
    ----------
    solver : ``"ipopt"`` (interior point, MUMPS) or ``"sqpmethod"`` (CasADi's SQP).
    qp_solver : QP solver of ``sqpmethod``: ``"qrqp"`` (default: CasADi's active-set QP),
        ``"qpoases"`` or ``"osqp"``. On the cross-method test's step qpOASES could not solve
        the QP of the solve from rest (its first nodes fixed, the rest conditions as
        equalities), and with OSQP the all-window SQP did not converge in 150 iterations;
        with qrqp both stages reached the other solvers' optimum (2026-11-26).
    tolerance : IPOPT's ``tol`` (scaled KKT error) and, for both solvers, the constraint
        violation at convergence [noise std]; ``sqpmethod``'s ``tol_pr`` and ``tol_du``, and
        its ``min_step_size`` (inf-norm over node states in noise std and log-parameters:
        ``NlpOutcome.small_step``).
    max_iter : NLP iterations.
    print_level : 0 silent; 1-12 IPOPT's ``print_level`` (``sqpmethod`` prints its
        iteration table for any level above 0).
    """

    solver: str = "ipopt"
    qp_solver: str = "qrqp"
    tolerance: float = 1e-10
    max_iter: int = 200
    print_level: int = 0

    def __post_init__(self) -> None:
        if self.solver not in SOLVERS:
            raise OptionError(f"solver must be one of {', '.join(SOLVERS)}, got {self.solver!r}")
        if not ca.has_nlpsol(self.solver):
            raise OptionError(f"solver {self.solver!r} is not available in this CasADi build")
        if self.qp_solver not in QP_SOLVERS:
            raise OptionError(
                f"qp_solver must be one of {', '.join(QP_SOLVERS)}, got {self.qp_solver!r}"
            )
        if self.solver == "sqpmethod" and not ca.has_conic(self.qp_solver):
            raise OptionError(f"qp_solver {self.qp_solver!r} is not available in this CasADi build")
        tol = self.tolerance
        if isinstance(tol, bool) or not isinstance(tol, int | float) or not 0 < tol < 1:
            raise OptionError(f"tolerance must be a number in (0, 1), got {tol!r}")
        for name, value, low, high in (
            ("max_iter", self.max_iter, 1, 100000),
            ("print_level", self.print_level, 0, 12),
        ):
            if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
                raise OptionError(
                    f"{name} must be a whole number in [{low}, {high}], got {value!r}"
                )


@dataclass
class NlpOutcome:
    """The NLP solver's result.

    Attributes
    ----------
    nodes : (W, n_x) node states [SI].
    theta : (n_f,) free log-parameters ln(p / p0) (inactive ones as given).
    converged : the solver reported success (IPOPT: solved to tolerance, or to an acceptable
        level) and the substep count was still stable at the solution.
    message : the solver's return status in words.
    iterations : NLP iterations over all (re)builds.
    cost : 1/2 sum r^2 at the solution (chi^2 / 2, as ``Evaluation.cost``).
    max_defect : largest continuity defect [noise std], as ``MultipleShooting.defects``.
    wall_time_s : build and solve [s].
    substeps : RK4 substeps per sample in every window.
    build_time_s : of that, building the NLP and the solver [s].
    small_step : ``sqpmethod`` stopped because its search direction fell below
        ``min_step_size`` before its dual tolerance was met (``stopped_on_small_step``):
        at an optimum, or where a QP failed; the caller judges which.
    """

    nodes: np.ndarray
    theta: np.ndarray
    converged: bool
    message: str
    iterations: int
    cost: float
    max_defect: float
    wall_time_s: float
    substeps: int
    build_time_s: float
    small_step: bool = False


class _Transcription:
    """The multiple-shooting NLP of ``ms`` in CasADi symbols, for a fixed substep count.

    The decision vector is node by node (z_i = node_i / s), then the active
    log-parameters. Two mapped window integrations build the graph: the state kernel for
    the residuals r and the defects (objective and constraints), and the sensitivity kernel
    (exact derivatives of the RK4 map, ``kernel.substep_function``) whose per-sample blocks
    d x_k / d(node, p_free) are gathered into the sparse Jacobians of r and of the defects.
    CasADi never differentiates through the record; it only multiplies J^T r and J^T J.
    """

    def __init__(self, ms: MultipleShooting, theta, active, smoothing, n_sub: int):
        problem = ms.problem
        if np.any(ms.output_states < 0):
            # The residuals below are C x: exact for outputs that are states only.
            others = [
                n for n, i in zip(problem.output_names, ms.output_states, strict=True) if i < 0
            ]
            raise OptionError(
                f"the NLP solvers take outputs that are coordinates or rates; model "
                f"{ms.model.variant} outputs {', '.join(others)}: use the Gauss-Newton solver"
            )
        self.ms = ms
        w, m, nx, ny = ms.n_windows, ms.m, ms.nx, ms.ny
        nf = len(problem.free)
        nd = nx + nf
        active = np.asarray(active, dtype=bool)
        active_index = np.flatnonzero(active)
        na = active_index.size
        z = ca.MX.sym("z", nx, w)
        theta_active = ca.MX.sym("theta", na)
        self.variables = ca.vertcat(ca.vec(z), theta_active)
        scale = ms.defect_scale
        nodes = z * ca.repmat(ca.DM(scale), 1, w)
        # p = p0 with the free entries p0_j exp(theta_j), or p0_j + s_j theta_j if signed
        # (FitProblem.parameters; held ones at their given theta).
        free = list(problem.free)
        theta_all = ca.DM(np.where(active, 0.0, theta)) + ca.DM(np.eye(nf)[:, active]) @ (
            theta_active
        )
        start, signed = ca.DM(problem.p_initial[free]), ca.DM(problem.linear.astype(float))
        p_free = (1 - signed) * start * ca.exp(theta_all) + signed * (
            start + ca.DM(problem.linear_scale) * theta_all
        )
        select_free = np.zeros((len(problem.p_initial), nf))
        select_free[free, np.arange(nf)] = 1.0
        p_fixed = problem.p_initial.copy()
        p_fixed[free] = 0.0
        p = ca.DM(p_fixed) + ca.DM(select_free) @ p_free
        threads = ms.transcription.threads
        inputs = (ca.DM(ms.inputs.reshape(w * m, ms.nu).T), p, ca.DM(smoothing), ms.dt / n_sub)

        # Residuals, ordered (window, sample, channel) like ms.weight; valid ones only.
        weight = ms.weight.reshape(w, m * ny).T  # (M n_y, W)
        valid = np.flatnonzero((weight > 0).ravel(order="F"))  # ca.vec is column-major
        c_blocks = ca.DM(np.kron(np.eye(m), ms.c))

        def residuals_and_defects(xs):
            per_window = ca.reshape(xs, nx * m, w)  # column i: window i after each sample
            states = ca.vertcat(nodes, per_window[: nx * (m - 1), :])  # samples 0 .. M - 1
            y = c_blocks @ states
            r = ca.vec(ca.DM(weight) * (y - ca.DM(ms.measured.reshape(w, m * ny).T)))
            x_end = per_window[nx * (m - 1) :, :]
            defects = (x_end[:, linked] - nodes[:, next_]) / ca.repmat(ca.DM(scale), 1, n_link)
            return r[valid.tolist()], ca.vec(defects)

        linked_windows = np.flatnonzero(ms.linked)
        linked, next_ = linked_windows.tolist(), (linked_windows + 1).tolist()
        n_link = linked_windows.size
        state_windows = window_function(_undifferentiated_substep(ms.model), n_sub, m, w, threads)
        self.residual, self.defects = residuals_and_defects(state_windows(nodes, *inputs))

        sens_windows = window_function(
            compiled_substep(ms.model, tuple(free)), n_sub, m, w, threads
        )
        xs, sens = sens_windows(nodes, *inputs)
        residual, defects = residuals_and_defects(xs)
        # Per-sample blocks d x / d(z, theta_free): column scaling by s (nodes) and p_free
        # (log-parameters), (n_x, n_d) each, column-major, window by window.
        columns = ca.vertcat(ca.DM(scale), p_free).T
        per_window = ca.reshape(sens, nx * nd * m, w)
        eye = ca.repmat(ca.DM(np.eye(nx, nd).ravel(order="F")), 1, w)
        at_samples = ca.reshape(ca.vertcat(eye, per_window[: nx * nd * (m - 1), :]), nx, -1)
        at_samples = at_samples * ca.repmat(columns, nx, m * w)
        # d r / d(z, theta): weight * C * block; entry (j, (i M + k) n_d + d) of g_res.
        row_weight = np.repeat(ms.weight.reshape(w * m, ny).T, nd, axis=1)
        g_res = ca.vec(ca.DM(row_weight) * (ca.DM(ms.c) @ at_samples))
        at_end = ca.reshape(per_window[nx * nd * (m - 1) :, :], nx, -1)
        at_end = at_end * ca.repmat(columns, nx, w) / ca.repmat(ca.DM(scale), 1, nd * w)
        g_def = ca.vertcat(ca.vec(at_end), -1.0)
        n_v = nx * w + na
        block_cols = np.concatenate([np.arange(nx), nx + active_index])  # d of each column

        # Jacobian of the residuals: row q (valid (i, k, j)) x columns of window i and theta.
        q = valid
        win, k, j = q // (m * ny), (q // ny) % m, q % ny
        rows = np.repeat(np.arange(q.size), nx + na)
        cols = np.concatenate(
            [
                win[:, None] * nx + np.arange(nx),
                nx * w + np.broadcast_to(np.arange(na), (q.size, na)),
            ],
            axis=1,
        ).ravel()
        entry = (j[:, None] + ny * ((win * m + k)[:, None] * nd + block_cols)).ravel()
        self.jac_residual = _sparse(q.size, n_v, rows, cols, g_res, entry)
        # Jacobian of the defects: row (link l, state r) x window i's z, theta, z_{i+1}.
        link, r_state = np.divmod(np.arange(n_link * nx), nx)
        i = linked_windows[link]
        rows = np.repeat(np.arange(n_link * nx), nx + na + 1)
        cols = np.concatenate(
            [
                i[:, None] * nx + np.arange(nx),
                nx * w + np.broadcast_to(np.arange(na), (i.size, na)),
                ((i + 1) * nx + r_state)[:, None],
            ],
            axis=1,
        ).ravel()
        entry = np.concatenate(
            [
                r_state[:, None] + nx * (i[:, None] * nd + block_cols),
                np.full((i.size, 1), nx * nd * w),  # the -1 of -z_{i+1}
            ],
            axis=1,
        ).ravel()
        self.jac_defects = _sparse(n_link * nx, n_v, rows, cols, g_def, entry)
        self.sens_residual, self.sens_defects = residual, defects
        self.n_defects = n_link * nx
        self._append_priors(problem, active, theta_active, nx * w)
        self._append_rest_conditions(ms, z)

    def _append_rest_conditions(self, ms: MultipleShooting, z: ca.MX) -> None:
        """Rows C_i (s z_i) after the defects: the directions ``C_i`` in which a record's
        first node at rest may not move beyond its fixed entries (``rest_conditions``),
        held at the start's values by their bounds (``rest_targets``)."""
        self.rest = rest_conditions(ms)
        if not self.rest:
            return
        scaled = [(i, c * ms.defect_scale[None, :]) for i, c in self.rest]
        conditions = ca.vertcat(*[ca.DM(c) @ z[:, i] for i, c in scaled])
        rows = np.vstack([c for _, c in scaled])
        first = np.concatenate([np.full(len(c), i) for i, c in scaled])
        self.defects = ca.vertcat(self.defects, conditions)
        self.sens_defects = ca.vertcat(self.sens_defects, conditions)
        r, k = np.nonzero(rows)
        cols = first[r] * ms.nx + k
        order = np.lexsort((r, cols))
        sparsity = ca.Sparsity.triplet(
            len(rows), self.variables.shape[0], r[order].tolist(), cols[order].tolist()
        )
        jac = ca.MX(ca.DM(sparsity, rows[r[order], k[order]]))
        self.jac_defects = ca.vertcat(self.jac_defects, jac)

    def rest_targets(self, nodes: np.ndarray) -> np.ndarray:
        """The rest conditions' values at ``nodes`` (W, n_x) [SI]: their bounds."""
        return np.concatenate([c @ nodes[i] for i, c in self.rest] or [np.zeros(0)])

    def _append_priors(self, problem, active: np.ndarray, theta_active, offset: int) -> None:
        """Rows w theta of the active parameters' priors (``FitProblem.prior_weight``)
        after the residuals, with their Jacobian (w at the parameter's column)."""
        weight = problem.prior_weight[active]
        k = np.flatnonzero(weight)
        if not k.size:
            return
        prior = ca.DM(weight[k]) * theta_active[k.tolist()]
        self.residual = ca.vertcat(self.residual, prior)
        self.sens_residual = ca.vertcat(self.sens_residual, prior)
        n_v = self.variables.shape[0]
        rows = ca.Sparsity.triplet(k.size, n_v, list(range(k.size)), (offset + k).tolist())
        self.jac_residual = ca.vertcat(self.jac_residual, ca.MX(ca.DM(rows, weight[k])))

    def nlpsol(self, settings: NlpSettings) -> ca.Function:
        """The solver: objective 1/2 |r|^2, constraints the defects, derivatives from the
        sensitivity kernel and the Gauss-Newton Hessian J^T J (as CasADi's sysid example)."""
        v, r, jac = self.variables, self.sens_residual, self.jac_residual
        none = ca.MX.sym("p", 0)
        f = 0.5 * ca.sumsqr(r)
        sigma = ca.MX.sym("sigma")
        lam_g = ca.MX.sym("lam_g", self.defects.shape[0])
        # IPOPT takes the upper triangle, sqpmethod the whole (symmetric) matrix.
        gauss_newton = jac.T @ jac
        triangle = settings.solver == "ipopt"
        hess = ca.Function(
            "nlp_hess_l",
            [v, none, sigma, lam_g],
            [sigma * (ca.triu(gauss_newton) if triangle else gauss_newton)],
            ["x", "p", "lam_f", "lam_g"],
            ["triu_hess_gamma_x_x" if triangle else "hess_gamma_x_x"],
        )
        nlp = {"x": v, "f": 0.5 * ca.sumsqr(self.residual), "g": self.defects}
        options: dict = {
            "hess_lag": hess,
            "print_time": False,
            "calc_lam_p": False,
            "calc_lam_x": False,
        }
        derivatives = [f, jac.T @ r, self.sens_defects, self.jac_defects]
        names = ["f", "grad_f_x", "g", "jac_g_x"]
        if settings.solver == "ipopt":
            options["grad_f"] = ca.Function(
                "nlp_grad_f", [v, none], derivatives[:2], ["x", "p"], names[:2]
            )
            options["jac_g"] = ca.Function(
                "nlp_jac_g", [v, none], derivatives[2:], ["x", "p"], names[2:]
            )
            options["ipopt"] = {
                "tol": settings.tolerance,
                "constr_viol_tol": settings.tolerance,
                "max_iter": settings.max_iter,
                "print_level": settings.print_level,
                "sb": "yes",
                "mu_strategy": "adaptive",
            }
        else:
            options["jac_fg"] = ca.Function("nlp_jac_fg", [v, none], derivatives, ["x", "p"], names)
            verbose = settings.print_level > 0
            options.update(
                {
                    "qpsol": settings.qp_solver,
                    "tol_pr": settings.tolerance,
                    "tol_du": settings.tolerance,
                    "min_step_size": settings.tolerance,
                    "max_iter": settings.max_iter,
                    "print_header": verbose,
                    "print_iteration": verbose,
                    "print_status": verbose,
                    "qpsol_options": _qp_options(settings.qp_solver),
                }
            )
        return ca.nlpsol("hframe_fit", settings.solver, nlp, options)


@lru_cache(maxsize=8)
def _undifferentiated_substep(model) -> ca.Function:
    """The compiled RK4 substep without sensitivities (``kernel.compiled_state_substep``,
    ~20x cheaper than with them), declared to have finite-difference derivatives only.

    The NLP's f and g are evaluated with it; every derivative the solvers use is given
    (``grad_f``, ``jac_g``/``jac_fg``, ``hess_lag`` from the sensitivity kernel). IPOPT's
    interface still builds a gradient function of f and g when it is created (never called
    here: ``calc_lam_x`` and ``calc_lam_p`` are off), which needs some derivative to exist.
    """
    substep = compiled_state_substep(model)
    symbols = [ca.MX.sym(substep.name_in(i), substep.sparsity_in(i)) for i in range(5)]
    return ca.Function(
        "rk4_substep_fd",
        symbols,
        substep.call(symbols),
        {
            "enable_forward": False,
            "enable_reverse": False,
            "enable_jacobian": True,
            "enable_fd": True,
        },
    )


def stopped_on_small_step(settings: NlpSettings, stats: dict) -> bool:
    """Whether ``sqpmethod`` stopped because its search direction fell below
    ``min_step_size`` (``settings.tolerance``) before its dual tolerance was met. Its
    ``tol_du`` is absolute: with a Gauss-Newton Hessian of ~1e4 (chi^2 / 2 per unit of the
    scaled variables) a step of 1e-10 is a gradient of ~1e-6, so at an optimum the step
    falls below ``min_step_size`` before the gradient below ``tol_du`` (the shipped six steps
    stopped there, at the other solvers' optimum within 2e-10 relative). A QP the SQP could
    not solve also ends there (no step), so this is no verdict by itself."""
    return (
        settings.solver == "sqpmethod"
        and stats.get("return_status") == "Search_Direction_Becomes_Too_Small"
    )


def _qp_options(name: str) -> dict:
    """Options of a QP solver of ``sqpmethod``: silent, and a QP it cannot solve is the SQP
    iteration's verdict (its return status), not an exception out of the fit."""
    quiet = {
        "qpoases": {"printLevel": "none"},
        "osqp": {"osqp": {"verbose": False}},
        "qrqp": {"print_iter": False, "print_header": False},
    }[name]
    return {**quiet, "error_on_fail": False}


def rest_conditions(ms: MultipleShooting) -> list[tuple[int, np.ndarray]]:
    """Per first window whose node may move only within a subspace beyond its fixed entries
    (``MultipleShooting.node_projector``: a record at rest, positions along the rigid
    modes): (window, C (c, n_x)), C's rows an orthonormal basis of the other directions
    among the entries that are not fixed (those the bounds hold)."""
    conditions = []
    for i in ms.first_window:
        projector = ms.node_projector[i]
        if np.array_equal(projector, np.diag(np.diagonal(projector))):
            continue
        loose = ~ms.fixed_node[i]
        values, vectors = np.linalg.eigh(np.eye(int(loose.sum())) - projector[np.ix_(loose, loose)])
        rows = np.zeros((int(np.count_nonzero(values > 0.5)), ms.nx))
        rows[:, loose] = vectors[:, values > 0.5].T
        conditions.append((int(i), rows))
    return conditions


def _sparse(n_rows, n_cols, rows, cols, values: ca.MX, entry: np.ndarray) -> ca.MX:
    """(n_rows, n_cols) MX with the nonzeros ``values[entry]`` at (rows, cols) (no two
    alike): a constant gather, ordered column-major as CasADi stores nonzeros."""
    order = np.lexsort((rows, cols))
    sparsity = ca.Sparsity.triplet(n_rows, n_cols, rows[order].tolist(), cols[order].tolist())
    return ca.MX(sparsity, values[entry[order].tolist()])


def solve_nlp(
    ms: MultipleShooting,
    nodes: np.ndarray,
    theta: np.ndarray,
    active: np.ndarray,
    smoothing: tuple[float, float],
    settings: NlpSettings | None = None,
    substeps: int | None = None,
) -> NlpOutcome:
    """Solve the multiple-shooting problem of ``ms`` with a CasADi NLP solver.

    Parameters
    ----------
    ms : the transcription (windows, data, weights); not modified.
    nodes : (W, n_x) initial node states [SI], e.g. ``ms.initial_nodes(p)[0]``.
    theta : (n_f,) initial free log-parameters ln(p / p0).
    active : (n_f,) bool: parameters being fitted; the others stay at ``theta``.
    smoothing : Coulomb smoothing velocities (linear [m/s], angular [rad/s]).
    settings : solver, tolerance, iterations, printing (default ``NlpSettings()``).
    substeps : RK4 substeps per sample in every window; default the stiff count of
        ``ms.substep_plan`` at ``theta`` (what the Gauss-Newton final stage uses).

    Returns
    -------
    NlpOutcome
    """
    settings = settings or NlpSettings()
    start = time.perf_counter()
    problem = ms.problem
    active = np.asarray(active, dtype=bool)
    theta = np.asarray(theta, dtype=float).copy()
    nodes = np.asarray(nodes, dtype=float).copy()
    plan = ms.substep_plan(problem.parameters(theta), smoothing)
    if plan["refused"] and not substeps:
        return _refused(nodes, theta, plan["stiff"], ms.transcription.max_substeps, start)
    n_sub = substeps or plan["stiff"]
    build_time = 0.0
    iterations = 0
    for _ in range(MAX_REBUILDS + 1):
        built = time.perf_counter()
        nlp = _Transcription(ms, theta, active, smoothing, n_sub)
        solver = nlp.nlpsol(settings)
        build_time += time.perf_counter() - built
        x0 = np.concatenate([(nodes / ms.defect_scale).ravel(), theta[active]])
        # Known nodes (a record's start at rest) are fixed: equal bounds.
        known = np.where(ms.fixed_node, nodes / ms.defect_scale, np.nan).ravel()
        lower = np.concatenate(
            [np.where(np.isnan(known), -np.inf, known), problem.theta_lower[active]]
        )
        upper = np.concatenate(
            [np.where(np.isnan(known), np.inf, known), problem.theta_upper[active]]
        )
        held = np.concatenate([np.zeros(nlp.n_defects), nlp.rest_targets(nodes)])
        solution = solver(x0=x0, lbx=lower, ubx=upper, lbg=held, ubg=held)
        stats = solver.stats()
        iterations += int(stats.get("iter_count", 0))
        v = np.array(solution["x"]).ravel()
        nodes = v[: nodes.size].reshape(nodes.shape) * ms.defect_scale
        theta[active] = v[nodes.size :]
        plan = ms.substep_plan(problem.parameters(theta), smoothing)
        needed = plan["stiff"]
        if needed <= n_sub or plan["refused"]:
            break
        n_sub = needed
    defects = np.array(solution["g"]).ravel()[: nlp.n_defects]
    message = str(stats["return_status"]).replace("_", " ")
    if plan["refused"]:
        message = stopped_message(needed, ms.transcription.max_substeps)
    return NlpOutcome(
        nodes=nodes,
        theta=theta,
        converged=bool(stats["success"]) and needed <= n_sub,
        message=message,
        iterations=iterations,
        cost=float(solution["f"]),
        max_defect=float(np.max(np.abs(defects), initial=0.0)),
        wall_time_s=time.perf_counter() - start,
        substeps=n_sub,
        build_time_s=build_time,
        small_step=stopped_on_small_step(settings, stats) and needed <= n_sub,
    )


def _refused(nodes, theta, needed: int, max_substeps: int, start: float) -> NlpOutcome:
    """The outcome of a solve from a point refused for its stiffness (stability at rest
    needs ``needed`` RK4 substeps, more than ``max_substeps``): nothing built or solved."""
    return NlpOutcome(
        nodes=nodes,
        theta=theta,
        converged=False,
        message=stopped_message(needed, max_substeps),
        iterations=0,
        cost=float("inf"),
        max_defect=float("nan"),
        wall_time_s=time.perf_counter() - start,
        substeps=needed,
        build_time_s=0.0,
    )
