"""Multiple-shooting transcription of a fit problem.

Every experiment is cut into windows of M samples (``FitOptions.shooting_interval``); the
state at the start of each window (a shooting node) is a decision variable, initialised from
the measurements. One evaluation integrates all windows of all experiments at once (one
mapped CasADi call) and returns, for every window,

- the weighted output residuals r = w (h(x_k, u_k, p) - y_k) of its samples (0 where
  invalid), h the model's output map (``Model.output_map``; a selection of states where every
  output is a coordinate or a rate),
- their Jacobian with respect to the window's node state and the free log-parameters,
- the state at the window's end and its Jacobian (A, B) for the continuity conditions
  x_end(node_i, p) = node_{i+1}.

Substeps per window: the smoothed Coulomb law makes the dynamics stiff only while a motor
turns slower than a few smoothing velocities (eigenvalue tau_c / (v_s J) ~ 4.5e4 1/s at rest,
~300 1/s in motion). Windows in which every stiff velocity keeps its sign and stays clear of
zero are integrated with the few substeps the belt modes need; the others with the substeps
the at-rest eigenvalue needs (``stable_substeps``). The split is checked on the computed
trajectory and a window is recomputed with the fine step if the check fails, so the result
is the same as with fine steps everywhere (to the integrator's truncation error, ~1e-8 rad).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from hframe_id.fitting.dataset import state_outputs
from hframe_id.fitting.kernel import (
    compiled_state_substep,
    compiled_substep,
    compiled_windows,
    window_function,
)
from hframe_id.fitting.link_options import TranscriptionOptions
from hframe_id.fitting.options import FitOptions
from hframe_id.fitting.problem import FitProblem, output_matrix, rest_projector
from hframe_id.fitting.shooting_nodes import ShootingNodes
from hframe_id.fitting.substep_plan import (
    coordinate_smoothing,
    plan_substeps,
    rest_and_moving_jacobians,
)

#: Window groups are padded to a multiple of this, so mapped functions are reused.
PAD = 16


@dataclass
class Evaluation:
    """Residuals and derivatives at one point (arrays indexed by window first)."""

    residual: np.ndarray  # (W, M, n_y) weighted residuals
    jac_node: np.ndarray | None  # (W, M, n_y, n_x); None: evaluated without derivatives
    jac_theta: np.ndarray | None  # (W, M, n_y, n_f) w.r.t. free log-parameters
    x_end: np.ndarray  # (W, n_x)
    a_end: np.ndarray | None  # (W, n_x, n_x) d x_end / d node
    b_end: np.ndarray | None  # (W, n_x, n_f) d x_end / d theta
    states: np.ndarray  # (W, M + 1, n_x) states at the window's samples and its end
    n_substeps: tuple[int, int]  # (fast, stiff)
    n_stiff_windows: int
    #: (n_f,) residuals of the free parameters' priors, w theta (0: no prior)
    prior_residual: np.ndarray | None = None

    @property
    def cost(self) -> float:
        """0.5 |r|^2 of the weighted residuals (chi^2 / 2 with the noise-model weights), the
        priors' residuals included."""
        prior = 0.0 if self.prior_residual is None else float(np.sum(self.prior_residual**2))
        return 0.5 * (float(np.sum(self.residual**2)) + prior)


def _range_basis(projector: np.ndarray) -> np.ndarray:
    """(n, r) orthonormal basis of an orthogonal projector's range: its identity columns
    where it is diagonal (0 or 1 on the diagonal), else its unit eigenvectors."""
    if np.array_equal(projector, np.diag(np.diagonal(projector))):
        return np.eye(len(projector))[:, np.diagonal(projector) > 0.5]
    values, vectors = np.linalg.eigh(projector)
    return vectors[:, values > 0.5]


def default_transcription(problem: FitProblem) -> TranscriptionOptions:
    """The transcription ``FitOptions()`` gives ``problem``'s model: its declared
    ``fit_defaults`` (shooting interval, continuity), else the library's."""
    return FitOptions().for_model(problem.initial.variant).transcription_options


class MultipleShooting(ShootingNodes):
    """The windows, data layout and evaluation of one problem (its nodes' starting values:
    ``ShootingNodes``)."""

    def __init__(
        self,
        problem: FitProblem,
        interval: int | None = None,
        transcription: TranscriptionOptions | None = None,
    ):
        """``transcription``: windows, continuity, substeps, threads (a fit passes its
        ``FitOptions.transcription_options``; default: the model's, those of ``FitOptions()``
        for its variant, ``FitOptions.for_model``); ``interval`` overrides its window
        length."""
        self.problem = problem
        self.transcription = transcription or default_transcription(problem)
        self.model = problem.model
        self.m = int(interval or self.transcription.shooting_interval)
        self.dt = problem.sample_period_s
        self.nx = self.model.n_states
        self.nq = self.nx // 2
        self.nu = self.model.n_inputs
        self.ny = len(self.model.outputs)
        self.nf = len(problem.free)
        #: dy/dx at the start (``output_matrix``): the output map where outputs are states.
        self.c = output_matrix(self.model, problem.p_initial)
        #: (n_y,) the state each output is, -1 for another function (``state_outputs``).
        self.output_states = state_outputs(self.model)
        selection = bool(np.all(self.output_states >= 0))
        # Outputs are states: y_j = x[index_j] (no output map to evaluate).
        self._output_index = self.output_states if selection else None
        #: State rows whose sensitivities the residuals need (all for a general output map).
        self._sens_rows = self.output_states if selection else np.arange(self.nx)
        self._output_functions: dict[int, ca.Function] = {}
        self.threads = self.transcription.threads
        m = self.m
        exp_of, start, length = [], [], []
        for e, exp in enumerate(problem.experiments):
            n = exp.n_samples
            for k0 in range(0, n, m):
                exp_of.append(e)
                start.append(k0)
                length.append(min(m, n - k0))
        self.window_experiment = np.array(exp_of)
        self.window_start = np.array(start)
        self.window_length = np.array(length)
        self.n_windows = len(exp_of)
        w = self.n_windows
        self.inputs = np.zeros((w, m, self.nu))
        self.measured = np.zeros((w, m, self.ny))
        self.weight = np.zeros((w, m, self.ny))
        for i in range(w):
            exp = problem.experiments[exp_of[i]]
            k0, n = start[i], length[i]
            self.inputs[i, :n] = exp.inputs[k0 : k0 + n]
            self.inputs[i, n:] = exp.inputs[k0 + n - 1]
            valid = exp.valid[k0 : k0 + n]
            self.measured[i, :n] = np.where(valid, exp.measured[k0 : k0 + n], 0.0)
            self.weight[i, :n] = valid / problem.recording_std[exp_of[i]]
        # Windows i and i + 1 of the same experiment are joined by continuity (unless the
        # options ask for independent horizons: ``FitOptions.continuity``).
        self.linked = (self.window_experiment[:-1] == self.window_experiment[1:]) & (
            self.transcription.continuity == "exact"
        )
        self.window_index_in_experiment = self.window_start // m
        #: (W, n_x, n_x) orthogonal projector onto the steps each node may take: the
        #: identity, but for an experiment's first node where the record starts at rest
        #: (``Dataset.at_rest``): no velocity, and positions that move only along the
        #: model's rigid modes (``problem.rest_projector``), or none at all, the node at the
        #: replay's rest state (``TranscriptionOptions.rest_start`` "replay").
        self.node_projector = np.broadcast_to(np.eye(self.nx), (len(exp_of), self.nx, self.nx))
        self.node_projector = self.node_projector.copy()
        at_rest_first = [
            k0 == 0 and problem.experiments[e].at_rest for e, k0 in zip(exp_of, start, strict=True)
        ]
        replayed = self.transcription.rest_start == "replay"
        self.node_projector[np.array(at_rest_first, dtype=bool)] = (
            0.0 if replayed else rest_projector(self.model, problem.p_initial)
        )
        self.first_window = np.array(
            [int(np.argmax(self.window_experiment == e)) for e in range(len(problem.experiments))]
        )
        self._buffers: dict = {}
        #: Integrate every window with the substeps the stiffest needs (``uniform()``, the
        #: final stages): the few-substep shortcut for windows in motion is accurate to
        #: ~1e-8 per sample but differs from a uniform discretization by up to a noise sigma
        #: over a record.
        self.uniform_substeps = False
        #: The compiled window loops, with and without derivatives (None: no C compiler).
        self.native = {
            True: compiled_windows(self.model, tuple(problem.free)),
            False: compiled_windows(self.model, None),
        }
        self.defect_scale = self._defect_scale()

    def _defect_scale(self) -> np.ndarray:
        """(n_x,) state scale for continuity defects: a coordinate's, the noise of the channel
        measuring its position (or the smallest channel noise), its velocity's that over one
        sample; a coordinate measured only through its rate (a tachometer, a motor current)
        takes that channel's noise divided by dy/dqdot for its velocity, that times the
        sample period for its position."""
        std = self.problem.channel_std
        scale = np.full(self.nq, float(np.min(std)))
        rate = np.full(self.nq, np.nan)
        for j in range(self.ny):
            cq, cv = np.abs(self.c[j, : self.nq]), np.abs(self.c[j, self.nq :])
            if cq.any():
                scale[int(np.argmax(cq))] = std[j] / cq.max()
            elif cv.any():
                rate[int(np.argmax(cv))] = std[j] / cv.max()
        by_position = np.any(self.c[:, : self.nq] != 0, axis=0)
        from_rate = ~by_position & np.isfinite(rate)
        scale[from_rate] = rate[from_rate] * self.dt
        return np.concatenate([scale, scale / self.dt])

    def subset(self, windows: np.ndarray, linked: bool = True) -> MultipleShooting:
        """The same transcription restricted to some windows (consecutive ones linked, or
        none if ``linked`` is False)."""
        view = object.__new__(MultipleShooting)
        view.__dict__.update(self.__dict__)
        windows = np.asarray(windows)
        for name in (
            "window_experiment",
            "window_start",
            "window_length",
            "window_index_in_experiment",
            "node_projector",
            "inputs",
            "measured",
            "weight",
        ):
            setattr(view, name, getattr(self, name)[windows])
        view.n_windows = len(windows)
        consecutive = (np.diff(windows) == 1) & (
            self.window_experiment[windows[:-1]] == self.window_experiment[windows[1:]]
        )
        view.linked = consecutive if linked else np.zeros(len(windows) - 1, dtype=bool)
        view.first_window = np.flatnonzero(np.r_[True, ~view.linked])
        view._buffers = {}
        return view

    def uniform(self) -> MultipleShooting:
        """The same transcription with every window integrated with the substeps the
        stiffest needs (the all-window stages); this one is left as it is."""
        view = object.__new__(MultipleShooting)
        view.__dict__.update(self.__dict__)
        view._buffers = {}
        view.uniform_substeps = True
        return view

    @property
    def fixed_node(self) -> np.ndarray:
        """(W, n_x) True for the node entries that are known, not estimated (the velocities
        of a record's first node at rest): the projector's zero rows."""
        return ~np.any(self.node_projector, axis=2)

    @property
    def initial_state_bases(self) -> list[np.ndarray]:
        """Per experiment, an orthonormal basis (n_x, r) of the directions in which its
        initial state is estimated (``node_projector`` of its first window): identity
        columns where the projector is diagonal (a record in motion: all n_x)."""
        return [_range_basis(self.node_projector[i]) for i in self.first_window]

    @property
    def n_nuisance(self) -> int:
        """Estimated initial-state directions (the statistics' nuisance parameters)."""
        return sum(basis.shape[1] for basis in self.initial_state_bases)

    def residual_rms(self, cost: float) -> float:
        """Residual rms over the valid samples, in units of each channel's noise std, of a
        cost 1/2 sum(residual^2) (about 1 for a correct model on sim-rig data)."""
        n_valid = max(int(np.count_nonzero(self.weight)), 1)
        return math.sqrt(2 * cost / n_valid)

    def moving_windows(self, velocity: np.ndarray, smoothing, margin: int = 1) -> np.ndarray:
        """Indices of windows in which some coordinate moves faster than 20 smoothing
        velocities (from a velocity estimate (W, M + 1, n_q)), widened by ``margin``
        windows on each side within the experiment: the part of a record that carries
        dynamics (at rest, the dynamics are stiff and cost most to integrate)."""
        vs = coordinate_smoothing(self.model, smoothing)
        moving = np.any(np.abs(velocity) > 20 * vs, axis=(1, 2))
        widened = moving.copy()
        for shift in range(1, margin + 1):
            same_prev = np.r_[
                np.zeros(shift, bool),
                self.window_experiment[shift:] == self.window_experiment[:-shift],
            ]
            same_next = np.r_[
                self.window_experiment[:-shift] == self.window_experiment[shift:],
                np.zeros(shift, bool),
            ]
            widened |= np.r_[np.zeros(shift, bool), moving[:-shift]] & same_prev
            widened |= np.r_[moving[shift:], np.zeros(shift, bool)] & same_next
        return np.flatnonzero(widened)

    # ------------------------------------------------------------------ substeps
    def substep_plan(self, p: np.ndarray, smoothing: tuple[float, float]) -> dict:
        """Fast and stiff substep counts, per velocity state the speed below which a window
        needs the stiff count, and whether the point is refused (stability at rest needs
        more than ``max_substeps``: ``evaluate`` integrates nothing there)."""
        a_rest, a_moving, vs = rest_and_moving_jacobians(self.model, p, smoothing)
        return plan_substeps(a_rest, a_moving, vs, self.dt, self.transcription)

    def _needs_stiff(self, velocity: np.ndarray, threshold: np.ndarray) -> np.ndarray:
        """(W,) windows whose velocities (W, K, n_q) come near zero or change sign."""
        check = threshold > 0
        if not np.any(check):
            return np.zeros(velocity.shape[0], dtype=bool)
        v = velocity[:, :, check]
        slow = np.any(np.abs(v) <= threshold[check], axis=(1, 2))
        flips = np.any(np.abs(np.diff(np.sign(v), axis=1)) > 0, axis=(1, 2))
        return slow | flips | ~np.all(np.isfinite(v), axis=(1, 2))

    def _integrate(self, idx: np.ndarray, nodes, p, smoothing, n_sub, out: dict) -> None:
        """Integrate windows ``idx`` with ``n_sub`` substeps per sample into ``out``: "xs"
        (W, M, n_x) the states after each sample and, if present, "sens" (W, M - 1, rows,
        n_d) the sensitivities to (node, free parameters) of the ``_sens_rows`` after samples
        1..M-1 and "end" (W, n_x, n_d) those of the window's end state. Evaluated on numpy
        buffers (no DM copies); only the sensitivities the residuals use are copied out."""
        count = len(idx)
        run, arrays, size = self._runner(n_sub, count, "sens" in out)
        sel = np.concatenate([idx, np.full(size - count, idx[-1])])
        arrays["x0"][:size] = nodes[sel]
        arrays["u"][: size * self.m] = self.inputs[sel].reshape(size * self.m, self.nu)
        arrays["p"][:] = p
        arrays["s"][:] = smoothing
        arrays["h"][0] = self.dt / n_sub
        if run() != 0:
            raise FloatingPointError("shooting window evaluation failed")
        out["xs"][idx] = arrays["xs"].reshape(-1, self.m, self.nx)[:count]
        if "sens" in out:
            # Column-major (n_x, n_d) per sample: a C-order (n_d, n_x) block.
            ss = arrays["ss"].reshape(-1, self.m, self.nx + self.nf, self.nx)[:count]
            out["sens"][idx] = ss[:, :-1, :, self._sens_rows].transpose(0, 1, 3, 2)
            out["end"][idx] = ss[:, -1].transpose(0, 2, 1)

    def _runner(self, n_sub: int, count: int, derivatives: bool):
        """(run, arrays, size) for integrating ``count`` windows: run() integrates the first
        ``size`` windows of ``arrays`` (``count``; the CasADi fallback pads to PAD, so that
        its mapped functions are reused) and returns the status."""
        kernel = self.native[derivatives]
        if kernel is None:
            size = int(math.ceil(count / PAD) * PAD)
            return (*self._buffer(n_sub, size, derivatives), size)
        key = ("native", derivatives)
        if key not in self._buffers:
            self._buffers[key] = self._arrays(self.n_windows, derivatives)
        arrays = self._buffers[key]

        def run() -> int:
            return kernel(arrays, float(arrays["h"][0]), n_sub, self.m, count, self.threads)

        return run, arrays, count

    def _arrays(self, windows: int, derivatives: bool) -> dict:
        """Input and output arrays of a window integration. CasADi matrices are
        column-major: a (rows, cols) input is a C-order (cols, rows)."""
        arrays = {
            "x0": np.zeros((windows, self.nx)),
            "u": np.zeros((windows * self.m, self.nu)),
            "p": np.zeros(len(self.model.parameters)),
            "s": np.zeros(2),
            "h": np.zeros(1),
            "xs": np.zeros((windows * self.m, self.nx)),
        }
        if derivatives:
            arrays["ss"] = np.zeros((windows * self.m * (self.nx + self.nf), self.nx))
        return arrays

    def _buffer(self, n_sub: int, padded: int, derivatives: bool):
        """(run, arrays) of the CasADi-mapped window function for ``padded`` windows (where
        no C compiler builds the native loop), its inputs and outputs bound once to numpy
        arrays; run() returns the function's status."""
        key = (n_sub, padded, derivatives)
        if key not in self._buffers:
            free = tuple(self.problem.free)
            substep = compiled_substep(self.model, free) if derivatives else None
            substep = substep or compiled_state_substep(self.model)
            fn = window_function(substep, n_sub, self.m, padded, self.threads)
            buf, trigger = fn.buffer()
            arrays = self._arrays(padded, derivatives)
            for i, name in enumerate(("x0", "u", "p", "s", "h")):
                buf.set_arg(i, memoryview(arrays[name]))
            for i, name in enumerate(("xs", "ss")[: 1 + derivatives]):
                buf.set_res(i, memoryview(arrays[name]))

            def run(buf=buf, trigger=trigger) -> int:
                trigger()
                return buf.ret()

            self._buffers[key] = (run, arrays)
        return self._buffers[key]

    # ------------------------------------------------------------------ evaluation
    def evaluate(
        self,
        nodes: np.ndarray,
        theta: np.ndarray,
        smoothing: tuple[float, float],
        velocity_hint: np.ndarray | None = None,
        plan: dict | None = None,
        windows: np.ndarray | None = None,
        base: Evaluation | None = None,
        derivatives: bool = True,
    ) -> Evaluation:
        """Residuals, Jacobians and window ends at (nodes, theta).

        With ``windows`` (and ``base``), only those windows are integrated; the others are
        taken from ``base`` (which must be at the same theta for the result to be one point).
        Without ``derivatives``, the Jacobian fields are None (a residual-only kernel, ~20x
        cheaper: for comparing costs).
        """
        p = self.problem.parameters(theta)
        plan = self._stage_plan(plan or self.substep_plan(p, smoothing))
        if plan["refused"]:
            return self._refused(plan, theta, derivatives)
        w, m, nx, nd = self.n_windows, self.m, self.nx, self.nx + self.nf
        todo = np.arange(w) if windows is None else np.asarray(windows)
        if velocity_hint is None:
            velocity_hint = np.repeat(nodes[:, None, self.nq :], m + 1, axis=1)
        out = {"xs": np.empty((w, m, nx))}
        if derivatives:
            out["sens"] = np.empty((w, m - 1, len(self._sens_rows), nd))
            out["end"] = np.empty((w, nx, nd))
        stiff = self._integrate_split(todo, nodes, p, smoothing, plan, velocity_hint, out)
        t = slice(None) if windows is None else todo
        parts = self._residuals(nodes, p, t, out, derivatives)
        prior = self.problem.prior_weight * np.asarray(theta)
        if windows is None:
            return Evaluation(
                **parts,
                n_substeps=(plan["fast"], plan["stiff"]),
                n_stiff_windows=int(stiff.sum()),
                prior_residual=prior,
            )
        merged = {}
        for name, value in parts.items():
            if value is None:
                merged[name] = None
                continue
            array = getattr(base, name).copy()
            array[t] = value
            merged[name] = array
        return Evaluation(
            **merged,
            n_substeps=(plan["fast"], plan["stiff"]),
            n_stiff_windows=base.n_stiff_windows,
            prior_residual=prior,
        )

    def _refused(self, plan: dict, theta: np.ndarray, derivatives: bool) -> Evaluation:
        """The evaluation of a point whose stiffness at rest needs more RK4 substeps for
        stability than ``max_substeps`` allows: infinite residuals (every solver refuses a
        step there, and a start there fails) and undefined derivatives, nothing integrated.
        Integrating it would cost the stability count in every stiff window; integrating it
        with fewer substeps would be unstable (``substeps_for_radius``)."""
        w, m, nx, ny, nf = self.n_windows, self.m, self.nx, self.ny, self.nf
        undefined = (lambda *shape: np.full(shape, np.nan)) if derivatives else (lambda *_: None)
        return Evaluation(
            residual=np.full((w, m, ny), np.inf),
            jac_node=undefined(w, m, ny, nx),
            jac_theta=undefined(w, m, ny, nf),
            x_end=np.full((w, nx), np.nan),
            a_end=undefined(w, nx, nx),
            b_end=undefined(w, nx, nf),
            states=np.full((w, m + 1, nx), np.nan),
            n_substeps=(plan["fast"], plan["stiff"]),
            n_stiff_windows=0,
            prior_residual=self.problem.prior_weight * np.asarray(theta),
        )

    def _stage_plan(self, plan: dict) -> dict:
        """The substep plan with ``uniform()``'s setting applied."""
        if self.uniform_substeps:
            plan = {**plan, "fast": plan["stiff"]}
        return plan

    def _integrate_split(self, todo, nodes, p, smoothing, plan, velocity_hint, out):
        """Integrate windows ``todo`` into ``out``, the stiff ones (by the velocity hint, then
        by the computed trajectory) with the stiff substeps. Returns the (W,) stiff flags."""
        w = self.n_windows
        stiff = np.zeros(w, dtype=bool)
        stiff[todo] = self._needs_stiff(velocity_hint[todo], plan["threshold"])
        pending = np.zeros(w, dtype=bool)
        pending[todo] = True
        xs = out["xs"]
        for attempt in range(2):
            for flag, n_sub in ((False, plan["fast"]), (True, plan["stiff"])):
                idx = np.flatnonzero((stiff == flag) & pending)
                if idx.size:
                    self._integrate(idx, nodes, p, smoothing, n_sub, out)
            if plan["fast"] == plan["stiff"] or attempt == 1:
                break
            traj = np.concatenate([nodes[todo, None, :], xs[todo]], axis=1)[:, :, self.nq :]
            recheck = np.zeros(w, dtype=bool)
            recheck[todo] = (~stiff[todo]) & self._needs_stiff(traj, plan["threshold"])
            if not recheck.any():
                break
            pending = recheck
            stiff |= recheck
        return stiff

    def _residuals(self, nodes, p, t, out: dict, derivatives: bool) -> dict:
        """Evaluation fields of windows ``t`` from the integrated ``out``."""
        m, nx = self.m, self.nx
        xs = out["xs"][t]
        states_t = np.concatenate([nodes[t, None, :], xs], axis=1)  # (T, M + 1, n_x)
        weight = self.weight[t]
        if self._output_index is not None:
            y = states_t[:, :m, self._output_index]
        else:
            y, h_x, h_p = self._output_map(states_t[:, :m], self.inputs[t], p)
        parts = {
            "residual": weight * (y - self.measured[t]),
            "jac_node": None,
            "jac_theta": None,
            "x_end": xs[:, -1],
            "a_end": None,
            "b_end": None,
            "states": states_t,
        }
        if not derivatives:
            return parts
        # Sensitivities that overflow once weighted (a parameter run far off: a stiff,
        # unstable model) become inf / nan here, the solver's verdict on the step
        # (``GaussNewton._linear_model``), not numpy warnings on the user's terminal.
        with np.errstate(over="ignore", invalid="ignore"):
            sens = out["sens"][t]
            eye = np.eye(nx, nx + self.nf)[self._sens_rows]
            eye = np.broadcast_to(eye, (len(xs), 1, *eye.shape))
            sens_t = np.concatenate([eye, sens], axis=1)  # at samples 0..M-1
            if self._output_index is not None:
                jac = sens_t * weight[..., None]
            else:
                jac = np.einsum("wkjx,wkxd->wkjd", h_x, sens_t)
                jac[..., nx:] += h_p[..., list(self.problem.free)]
                jac *= weight[..., None]
            slopes = self.problem.parameter_slopes(p)  # d p / d theta
            end = out["end"][t]
            parts["jac_node"] = jac[..., :nx]
            parts["jac_theta"] = jac[..., nx:] * slopes
            parts["a_end"] = end[:, :, :nx]
            parts["b_end"] = end[:, :, nx:] * slopes
        return parts

    def _output_map(self, states: np.ndarray, inputs: np.ndarray, p: np.ndarray):
        """The model's output map at states (T, M, n_x) under inputs (T, M, n_u) [SI]:
        y (T, M, n_y), dy/dx (T, M, n_y, n_x) and dy/dp (T, M, n_y, n_p), one mapped call."""
        shape = states.shape[:2]
        count = shape[0] * shape[1]
        if count not in self._output_functions:
            x = ca.SX.sym("x", self.nx)
            u = ca.SX.sym("u", self.nu)
            q = ca.SX.sym("p", len(self.model.parameters))
            y = self.model.output_map(x, u, q)
            jacobians = [ca.densify(ca.jacobian(y, v)) for v in (x, q)]
            fn = ca.Function("output_jacobians", [x, u, q], [y, *jacobians])
            self._output_functions[count] = fn.map(count, "serial")
        y, h_x, h_p = self._output_functions[count](
            states.reshape(count, self.nx).T,
            inputs.reshape(count, self.nu).T,
            np.repeat(p[:, None], count, axis=1),
        )
        n_p = len(p)
        return (
            np.array(y).T.reshape(*shape, self.ny),
            np.array(h_x)
            .reshape(self.ny, count, self.nx)
            .transpose(1, 0, 2)
            .reshape(*shape, self.ny, self.nx),
            np.array(h_p)
            .reshape(self.ny, count, n_p)
            .transpose(1, 0, 2)
            .reshape(*shape, self.ny, n_p),
        )

    def defects(self, ev: Evaluation, nodes: np.ndarray, links=None) -> np.ndarray:
        """(W - 1, n_x) continuity defects x_end_i - node_{i+1}, scaled by the state scale;
        zero between experiments (and wherever ``links`` is False)."""
        links = self.linked if links is None else links
        d = (ev.x_end[:-1] - nodes[1:]) / self.defect_scale
        d[~links] = 0.0
        return d
