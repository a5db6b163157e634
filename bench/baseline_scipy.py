"""A careful single-shooting fit with SciPy, the baseline the multiple-shooting fitter is timed by.

Part of the benchmarks, not of the fitter: ``bench.fitting`` (``make bench``, section
fitting) runs it against ``fit_recordings`` from the same starts.

The problem is the fitter's (same model, same RK4 with the same substep rule, same residuals,
same free parameters); only the transcription and the solver differ. Each experiment is
simulated from its measured rest state over the whole record, and
``scipy.optimize.least_squares(method="trf")`` minimises the noise-weighted output error

    r = (y_sim(theta) - y_meas) / sigma,   p = p_0 exp(theta),

over the log parameters theta, bounded to p_0 x/÷ ``bound_factor`` (the fitter's bounds).
sigma is the encoder quantization step / sqrt(12) for motor angles and the laser noise std for
positions; samples a sensor flags invalid are left out.

Jacobian. Two fair choices are offered; the default is the stronger one:

- ``"sensitivities"`` (default): exact forward sensitivities S = dx/dp of the discrete RK4 map,
  propagated substep by substep alongside the state (the variational equations integrated with
  the same RK4 stages, which is exactly the derivative of the RK4 map). The substep is one flat
  SX graph compiled to native code, so a Jacobian costs about 1.5 simulations of CPU time (not
  1 + n_free) and has no step-size error. A user who has the model in CasADi would write this.
- ``"finite-differences"``: forward differences with step ``fd_step`` in theta (relative step
  in p), all 1 + n_free perturbed simulations of all experiments evaluated in one batched,
  threaded, compiled call. This is what a SciPy user without AD would write.

Nothing is made slow on purpose: the substeps are compiled by the project's native build
(``hframe_id.simulation.compiled``, cached on disk) and run under CasADi ``mapaccum`` (no Python
loop over samples), experiments run on all cores, results come back through CasADi's buffer
interface, and function objects are cached per substep count.
"""

from __future__ import annotations

import ctypes
import difflib
import math
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import Literal

import casadi as ca
import numpy as np
from scipy.optimize import least_squares

from hframe_id.errors import FitError, OptionError
from hframe_id.fitting.dataset import Dataset
from hframe_id.fitting.problem import rigid_modes
from hframe_id.models import Model, build_model
from hframe_id.parameters import ParameterSet
from hframe_id.recordings.recording import Recording
from hframe_id.simulation.compiled import evaluate, maybe_compile
from hframe_id.simulation.integrators import rk4_substep, stable_substeps

#: Parameters the fitter keeps fixed by default (issue 5): pulley radius, motor constants and
#: motor 1's amplifier gain (the reference that makes the others identifiable). Everything else
#: a variant requires (stiffnesses, masses, inertias, viscous and Coulomb friction, g_2) is free.
FIXED_BY_DEFAULT = ("r", "K_t", "K_e", "R", "g_1")

JacobianMethod = Literal["sensitivities", "finite-differences"]


def default_free_names(variant: str) -> tuple[str, ...]:
    """The free parameters of the fitter's default for a model variant."""
    model = build_model(variant)
    return tuple(
        spec.name
        for spec in model.parameters
        if spec.required and spec.name not in FIXED_BY_DEFAULT
    )


@dataclass(frozen=True)
class BaselineOptions:
    """Options of the single-shooting baseline.

    Attributes
    ----------
    jacobian : ``"sensitivities"`` (exact, compiled forward sensitivities) or
        ``"finite-differences"`` (batched forward differences in the log parameters).
    fd_step : forward-difference step in log parameters (relative step in p). 1e-6 balances
        truncation (~1e-6 relative) against round-off of the simulated outputs (~1e-14 / 1e-6).
    bound_factor : each parameter is bounded to [p_0 / f, p_0 f] (the fitter's bounds).
    ftol, xtol, gtol : ``least_squares`` termination tolerances.
    x_scale : ``least_squares`` variable scale: a number (1 suits log parameters) or ``"jac"``
        (scale by the inverse Jacobian column norms, updated every iteration).
    tr_solver : ``least_squares`` trust-region subproblem solver: ``"exact"`` (an SVD of the
        Jacobian per iteration) or ``"lsmr"`` (iterative, a 2-D subspace step).
    max_nfev : cap on residual evaluations (None: no cap); a capped fit is not converged.
    max_time_s : cap on wall time [s] (None: no cap); a capped fit is not converged.
    n_threads : threads for evaluating experiments (and FD columns) in parallel.
    compile_c : compile the RK4 substep to C with the system compiler (falls back to CasADi's
        virtual machine when none is available).
    rest_state : initial state of each experiment, at rest at the pre-roll's mean readings:
        ``"relaxed"`` with the belts unstretched (see ``_rest_state``), or ``"measured"`` with
        every measured coordinate at its own reading.
    substep_safety, max_substeps : RK4 substeps per sample are chosen from the current
        parameters by ``stable_substeps`` with this safety factor and cap (the fitter's rule).
    verbose : ``least_squares`` verbosity (0, 1, 2; 2 prints every iteration).
    """

    jacobian: JacobianMethod = "sensitivities"
    fd_step: float = 1e-6
    bound_factor: float = 10.0
    ftol: float = 1e-8
    xtol: float = 1e-8
    gtol: float = 1e-8
    x_scale: float | Literal["jac"] = 1.0
    tr_solver: Literal["exact", "lsmr"] = "exact"
    max_nfev: int | None = 200
    max_time_s: float | None = None
    n_threads: int = 2
    compile_c: bool = True
    rest_state: Literal["relaxed", "measured"] = "relaxed"
    substep_safety: float = 1.5
    max_substeps: int = 200
    verbose: int = 0

    def __post_init__(self) -> None:
        if self.rest_state not in ("relaxed", "measured"):
            raise OptionError(
                f"rest_state must be 'relaxed' or 'measured', got {self.rest_state!r}"
            )
        if self.jacobian not in ("sensitivities", "finite-differences"):
            raise OptionError(
                f"jacobian must be 'sensitivities' or 'finite-differences', got {self.jacobian!r}"
            )
        if not (math.isfinite(self.fd_step) and 0 < self.fd_step < 0.1):
            raise OptionError(f"fd_step must be in (0, 0.1), got {self.fd_step}")
        if not (math.isfinite(self.bound_factor) and self.bound_factor > 1):
            raise OptionError(f"bound_factor must be > 1, got {self.bound_factor}")
        if not (self.x_scale == "jac" or isinstance(self.x_scale, int | float)):
            raise OptionError(f"x_scale must be a number or 'jac', got {self.x_scale!r}")
        for name in ("ftol", "xtol", "gtol") + (() if self.x_scale == "jac" else ("x_scale",)):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise OptionError(f"{name} must be > 0, got {value}")
        if self.tr_solver not in ("exact", "lsmr"):
            raise OptionError(f"tr_solver must be 'exact' or 'lsmr', got {self.tr_solver!r}")
        if self.max_nfev is not None and self.max_nfev < 1:
            raise OptionError(f"max_nfev must be >= 1 or None, got {self.max_nfev}")
        if self.max_time_s is not None and not self.max_time_s > 0:
            raise OptionError(f"max_time_s must be > 0 s or None, got {self.max_time_s}")
        if not (math.isfinite(self.substep_safety) and self.substep_safety >= 1):
            raise OptionError(f"substep_safety must be >= 1, got {self.substep_safety}")
        if self.max_substeps < 1:
            raise OptionError(f"max_substeps must be >= 1, got {self.max_substeps}")
        if self.n_threads < 1:
            raise OptionError(f"n_threads must be >= 1, got {self.n_threads}")
        if self.verbose not in (0, 1, 2):
            raise OptionError(f"verbose must be 0, 1 or 2, got {self.verbose}")


@dataclass
class BaselineResult:
    """Outcome of a single-shooting fit.

    Attributes
    ----------
    success : the solver met a tolerance and was not capped (parameters at a bound are
        named in ``at_bound`` and the message, as the fitter does).
    message : why it stopped.
    estimates : fitted value of every free parameter (SI).
    parameters : the full parameter set (fixed ones at their initial values).
    cost : 0.5 * sum of squared weighted residuals at the estimate.
    initial_cost : the same at the start.
    nfev, njev : residual and Jacobian evaluations.
    wall_time_s : wall time of the solve [s] (includes building functions for new substep
        counts; excludes the one-time compile, see ``setup_time_s``).
    setup_time_s : wall time of compiling the substep functions [s] (0 once cached).
    capped : stopped by ``max_nfev`` or ``max_time_s``.
    at_bound : free parameters that end at a bound.
    n_residuals : number of weighted residuals (valid samples x channels).
    jacobian : the Jacobian method used.
    """

    success: bool
    message: str
    estimates: dict[str, float]
    parameters: ParameterSet
    cost: float
    initial_cost: float
    nfev: int
    njev: int
    wall_time_s: float
    setup_time_s: float
    capped: bool
    at_bound: tuple[str, ...]
    n_residuals: int
    jacobian: str
    free_names: tuple[str, ...] = field(default=())


#: (get, set) thread-count functions of the OpenBLAS builds NumPy and SciPy wheels bundle.
_OPENBLAS_THREAD_FUNCTIONS = (
    ("scipy_openblas_get_num_threads", "scipy_openblas_set_num_threads"),
    ("scipy_openblas_get_num_threads64_", "scipy_openblas_set_num_threads64_"),
    ("openblas_get_num_threads", "openblas_set_num_threads"),
    ("openblas_get_num_threads64_", "openblas_set_num_threads64_"),
)


@contextmanager
def _single_threaded_blas() -> Iterator[None]:
    """Run the solver's dense linear algebra on one BLAS thread, then restore.

    trf factors the (n_residuals x n_free) Jacobian by SVD every iteration; for 22,000 x 16 this
    takes ~6 ms on one OpenBLAS thread but 30-200 ms with OpenBLAS's default threads on a
    loaded 2-core machine (threads spin against each other and the simulation threads). This
    is what ``threadpoolctl.threadpool_limits(1)`` would do, for the OpenBLAS copies NumPy and
    SciPy load; without OpenBLAS it does nothing.
    """
    libraries = []
    try:
        with open("/proc/self/maps") as maps:
            paths = {line.split()[-1] for line in maps if "openblas" in line.lower()}
    except OSError:
        paths = set()
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for get_name, set_name in _OPENBLAS_THREAD_FUNCTIONS:
            get = getattr(lib, get_name, None)
            set_ = getattr(lib, set_name, None)
            if get is not None and set_ is not None:
                libraries.append((set_, int(get())))
                set_(1)
                break
    try:
        yield
    finally:
        for set_, threads in libraries:
            set_(threads)


class _TimeLimit(Exception):
    """Raised inside the residual callbacks when ``max_time_s`` has passed."""


@lru_cache(maxsize=8)
def _substeps(model: Model, free: tuple[int, ...], compile_c: bool) -> tuple[ca.Function, ...]:
    """Compiled RK4 substeps of length h: plain (x, u, p, s, h) -> x+ and with sensitivities
    (x, S, u, p, s, h) -> (x+, S+), S = dx/dp_free (n_x x n_free).

    The sensitivity substep applies the same RK4 stages to the variational equation
    S' = f_x S + f_p, which is exactly the derivative of the RK4 map.
    """
    nx, nu, n_p = model.n_states, model.n_inputs, len(model.parameters)
    x = ca.SX.sym("x", nx)
    sens = ca.SX.sym("S", nx, len(free))
    u = ca.SX.sym("u", nu)
    p = ca.SX.sym("p", n_p)
    s = ca.SX.sym("s", 2)
    h = ca.SX.sym("h")
    xdot = model.dynamics(x, u, p, s)
    rates = ca.Function(
        "rates", [x, u, p, s], [xdot, ca.jacobian(xdot, x), ca.jacobian(xdot, p)[:, list(free)]]
    )

    # The state and its sensitivities stacked, z = [x; vec(S)], stepped by the project's RK4.
    n_free = len(free)
    z = ca.SX.sym("z", nx * (1 + n_free))
    f, f_x, f_p = rates(z[:nx], u, p, s)
    variational = f_x @ ca.reshape(z[nx:], nx, n_free) + f_p
    augmented = ca.Function("augmented", [z, u, p, s], [ca.vertcat(f, ca.vec(variational))])
    z_next = rk4_substep(augmented, ca.vertcat(x, ca.vec(sens)), u, p, s, h)
    x_next = rk4_substep(model.dynamics, x, u, p, s, h)
    sens_next = ca.reshape(z_next[nx:], nx, n_free)
    plain = ca.Function("ss_substep", [x, u, p, s, h], [x_next])
    with_sens = ca.Function("ss_substep_sens", [x, sens, u, p, s, h], [x_next, sens_next])
    # The project's native compilation (gcc, cached on disk; CasADi's VM without a compiler).
    return maybe_compile(plain, compile_c), maybe_compile(with_sens, compile_c)


@lru_cache(maxsize=64)
def _trajectory(
    substep: ca.Function, n_substeps: int, n_samples: int, n_columns: int, n_threads: int
) -> ca.Function:
    """(X0, U, P, s, h) -> states after each of n_samples samples (and their sensitivities if
    ``substep`` carries them) of n_columns records, in column blocks of n_samples; X0 is
    (n_x, C), U (n_u, C n_samples), P (n_p, C).
    """
    has_sens = substep.n_in() == 6
    nx = substep.size1_in(0)
    nu = substep.size1_in(2 if has_sens else 1)
    n_p = substep.size1_in(3 if has_sens else 2)
    x = ca.MX.sym("x", nx)
    u = ca.MX.sym("u", nu)
    p = ca.MX.sym("p", n_p)
    s = ca.MX.sym("s", 2)
    h = ca.MX.sym("h")
    uu = ca.MX.sym("U", nu, n_samples)
    if has_sens:
        sens = ca.MX.sym("S", nx, substep.size2_in(1))
        xk, sk = x, sens
        for _ in range(n_substeps):
            xk, sk = substep(xk, sk, u, p, s, h)
        sample = ca.Function("sample", [x, sens, u, p, s, h], [xk, sk])
        s0 = ca.DM.zeros(nx, substep.size2_in(1))
        outputs = sample.mapaccum("record", n_samples, 2)(x, s0, uu, p, s, h)
    else:
        xk = x
        for _ in range(n_substeps):
            xk = substep(xk, u, p, s, h)
        sample = ca.Function("sample", [x, u, p, s, h], [xk])
        outputs = [sample.mapaccum("record", n_samples)(x, uu, p, s, h)]
    record = ca.Function("record", [x, uu, p, s, h], outputs)
    if n_columns > 1 and n_threads > 1:
        return record.map(n_columns, "thread", min(n_threads, n_columns))
    return record.map(n_columns)


@dataclass(frozen=True)
class _Data:
    """The experiments' Datasets stacked for simulation: one column block per experiment,
    zero-padded to equal lengths."""

    x0: np.ndarray  # (n_x, E) measured rest states
    inputs: np.ndarray  # (n_u, E * (N - 1)) applied voltages of samples 0 .. N-2
    measured: np.ndarray  # (E, N, n_y)
    weights: np.ndarray  # (E, N, n_y) 1 / sigma
    mask: np.ndarray  # (E, N, n_y) valid samples (False on padding)
    output_matrix: np.ndarray  # (n_y, n_x) y = C x
    n_samples: int
    dt: float

    @property
    def n_experiments(self) -> int:
        """Number of experiments E."""
        return self.x0.shape[1]


def _rest_state(
    model: Model, p: np.ndarray, output_matrix: np.ndarray, data: Dataset, rest_state: str
) -> np.ndarray:
    """State at rest from each channel's mean valid reading over the pre-roll (the samples
    before the first non-zero command), weighted by sqrt(readings) / noise std.

    ``"measured"``: each measured coordinate at its mean reading, the others 0.
    ``"relaxed"``: the position with every belt spring relaxed (the model's only rest
    position with smoothed friction: ``rigid_modes``) that best fits the readings. The
    springs' null space ties the laser positions to the encoders, which resolve the belt
    0.1 um (r * encoder step / sqrt(12)), against 0.7 um for 50 averaged laser samples: a laser
    offset of that size in a stretched belt would shift the motors by ~6 encoder sigmas for the
    whole record and bias the fit.
    """
    moving = np.flatnonzero(np.any(data.recording.inputs != 0, axis=1))
    n_rest = max(int(moving[0]) if moving.size else data.n_samples, 1)
    rest_mean = np.zeros(len(data.names))
    rest_weight = np.zeros(len(data.names))
    for k, name in enumerate(data.names):
        rest = data.valid[:n_rest, k]
        if not rest.any():
            raise FitError(f"{data.name}: no valid {name!r} sample at rest to start from")
        rest_mean[k] = data.measured[:n_rest, k][rest].mean()
        rest_weight[k] = math.sqrt(rest.sum()) / data.noise_std[k]
    nq = len(model.coordinates)
    selection = output_matrix[:, :nq]
    x0 = np.zeros(model.n_states)
    if rest_state == "measured":
        x0[:nq] = np.linalg.lstsq(selection, rest_mean, rcond=None)[0]
        return x0
    null = rigid_modes(model, p)
    a = np.linalg.lstsq(
        rest_weight[:, None] * (selection @ null), rest_weight * rest_mean, rcond=None
    )[0]
    x0[:nq] = null @ a
    return x0


def _prepare(
    model: Model, recordings: Sequence[Recording], p0: np.ndarray, rest_state: str
) -> _Data:
    """The recordings on the model's channels (``Dataset``), stacked in equal-length column
    blocks, each starting from its rest state (``_rest_state``)."""
    dt = recordings[0].sample_period_s
    x_sym = ca.SX.sym("x", model.n_states)
    c_sym = ca.jacobian(model.output(x_sym), x_sym)
    if not c_sym.is_constant():
        raise FitError(f"{model.variant}: outputs are not a linear selection of the state")
    output_matrix = np.array(ca.DM(c_sym))
    n = max(rec.n_samples for rec in recordings)
    n_exp = len(recordings)
    x0 = np.zeros((model.n_states, n_exp))
    inputs = np.zeros((model.n_inputs, n_exp, n - 1))
    measured = np.zeros((n_exp, n, len(model.outputs)))
    weights = np.zeros_like(measured)
    mask = np.zeros(measured.shape, dtype=bool)
    for e, rec in enumerate(recordings):
        where = rec.name()
        if rec.variant != model.variant:
            raise FitError(f"{where}: recording of {rec.variant!r}, fitting {model.variant!r}")
        if not math.isclose(rec.sample_period_s, dt, rel_tol=1e-9):
            raise FitError(
                f"{where}: sample period {rec.sample_period_s} s differs from {dt} s of "
                f"{recordings[0].name()}; fit experiments of one sample rate together"
            )
        if rec.n_samples < 2:
            raise FitError(f"{where}: needs at least 2 samples, has {rec.n_samples}")
        steps = np.diff(rec.time_s)
        if not np.allclose(steps, dt, rtol=1e-6, atol=1e-9):
            raise FitError(f"{where}: samples are not uniformly spaced at {dt} s")
        data = Dataset.from_recording(model, rec)
        inputs[:, e, : rec.n_samples - 1] = data.inputs[:-1].T
        measured[e, : rec.n_samples] = np.where(data.valid, data.measured, 0.0)
        weights[e, : rec.n_samples] = 1.0 / data.noise_std
        mask[e, : rec.n_samples] = data.valid
        x0[:, e] = _rest_state(model, p0, output_matrix, data, rest_state)
    return _Data(
        x0=x0,
        inputs=inputs.reshape(model.n_inputs, -1),
        measured=measured,
        weights=weights,
        mask=mask,
        output_matrix=output_matrix,
        n_samples=n,
        dt=dt,
    )


class _SingleShooting:
    """Residuals and Jacobian of the output error over the log parameters theta = log(p / p_0)."""

    def __init__(
        self,
        model: Model,
        data: _Data,
        p0: np.ndarray,
        free: tuple[int, ...],
        options: BaselineOptions,
        deadline: float | None,
    ) -> None:
        self.model, self.data, self.p0, self.free, self.options = model, data, p0, free, options
        self.smoothing = model.options.smoothing
        self.plain, self.with_sens = _substeps(model, free, options.compile_c)
        self.deadline = deadline
        self.best: tuple[float, np.ndarray] = (math.inf, np.zeros(len(free)))
        self.nfev = 0
        self.njev = 0
        self.initial_cost = math.nan

    def parameters(self, theta: np.ndarray) -> np.ndarray:
        """The full parameter vector (SI) at log-parameters ``theta``: p = p_0 exp(theta)."""
        p = self.p0.copy()
        p[list(self.free)] = self.p0[list(self.free)] * np.exp(theta)
        return p

    def _check_time(self) -> None:
        # The start is always evaluated, so that even a capped result has a cost.
        if self.nfev and self.deadline is not None and time.perf_counter() > self.deadline:
            raise _TimeLimit

    def _substep_count(self, p: np.ndarray) -> int:
        return stable_substeps(
            self.model,
            p,
            self.data.dt,
            self.smoothing,
            safety=self.options.substep_safety,
            cap=self.options.max_substeps,
        )

    def _shared(self, p: np.ndarray, n_sub: int, columns: int) -> list[np.ndarray]:
        """Parameters, smoothing and substep length, one row per mapped column."""
        return [
            np.tile(p, (columns, 1)),
            np.tile(self.smoothing, (columns, 1)),
            np.full(columns, self.data.dt / n_sub),
        ]

    def _outputs(self, states: np.ndarray, columns: int) -> np.ndarray:
        """(C (N-1), n_x) states after each sample -> (C, N, n_y) outputs incl. the rest state."""
        d = self.data
        x = states.reshape(columns, d.n_samples - 1, self.model.n_states)
        x0 = np.tile(d.x0.T, (columns // d.n_experiments, 1))[:, None, :]
        return np.concatenate([x0, x], axis=1) @ d.output_matrix.T

    def _weighted(self, outputs: np.ndarray) -> np.ndarray:
        d = self.data
        return ((outputs - d.measured) * d.weights)[d.mask]

    def residuals(self, theta: np.ndarray) -> np.ndarray:
        """Noise-weighted output errors (y_sim - y_meas) / sigma over the valid samples;
        records the best cost seen."""
        self._check_time()
        self.nfev += 1
        d = self.data
        p = self.parameters(theta)
        n_sub = self._substep_count(p)
        e = d.n_experiments
        trajectory = _trajectory(self.plain, n_sub, d.n_samples - 1, e, self.options.n_threads)
        (states,) = evaluate(trajectory, [d.x0.T, d.inputs.T, *self._shared(p, n_sub, e)])
        r = self._weighted(self._outputs(states, e))
        if not np.all(np.isfinite(r)):
            r = np.where(np.isfinite(r), r, 1e10)  # diverged simulation: a large, finite cost
        cost = 0.5 * float(r @ r)
        if self.nfev == 1:
            self.initial_cost = cost
        if cost < self.best[0]:
            self.best = (cost, theta.copy())
        return r

    def jacobian(self, theta: np.ndarray) -> np.ndarray:
        """d residuals / d theta, by the options' method (sensitivities or differences)."""
        self._check_time()
        self.njev += 1
        if self.options.jacobian == "sensitivities":
            return self._jacobian_sensitivities(theta)
        return self._jacobian_differences(theta)

    def _jacobian_sensitivities(self, theta: np.ndarray) -> np.ndarray:
        d = self.data
        p = self.parameters(theta)
        n_sub = self._substep_count(p)
        e, nx, nf = d.n_experiments, self.model.n_states, len(self.free)
        trajectory = _trajectory(self.with_sens, n_sub, d.n_samples - 1, e, self.options.n_threads)
        _, sens = evaluate(trajectory, [d.x0.T, d.inputs.T, *self._shared(p, n_sub, e)])
        sens = sens.reshape(e, d.n_samples - 1, nf, nx)  # CasADi's column-major layout
        dy = np.einsum("yx,enjx->enyj", d.output_matrix, sens)
        dy = np.concatenate([np.zeros((e, 1, *dy.shape[2:])), dy], axis=1)
        # d r / d theta_j = w dy/dp_j p_j (p = p_0 exp(theta)); the rest state does not move.
        jac = dy * d.weights[..., None] * p[list(self.free)]
        return jac[d.mask]

    def _jacobian_differences(self, theta: np.ndarray) -> np.ndarray:
        d = self.data
        nf, e = len(self.free), d.n_experiments
        step = self.options.fd_step
        thetas = np.vstack([theta, theta + step * np.eye(nf)])  # (1 + nf, nf)
        ps = np.stack([self.parameters(t) for t in thetas], axis=1)  # (n_p, 1 + nf)
        n_sub = self._substep_count(ps[:, 0])  # one substep count for all columns
        columns = e * (nf + 1)
        trajectory = _trajectory(
            self.plain, n_sub, d.n_samples - 1, columns, self.options.n_threads
        )
        (states,) = evaluate(
            trajectory,
            [
                np.tile(d.x0.T, (nf + 1, 1)),
                np.tile(d.inputs.T, (nf + 1, 1)),
                np.repeat(ps.T, e, axis=0),
                *self._shared(ps[:, 0], n_sub, columns)[1:],
            ],
        )
        outputs = self._outputs(states, columns).reshape(nf + 1, e, d.n_samples, -1)
        base = self._weighted(outputs[0])
        return np.stack([(self._weighted(outputs[j + 1]) - base) / step for j in range(nf)], axis=1)


def _free_indices(model: Model, free_names: Sequence[str]) -> tuple[int, ...]:
    names = list(model.parameter_names)
    seen: set[str] = set()
    for name in free_names:
        if name not in names:
            close = difflib.get_close_matches(str(name), names, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise FitError(f"{model.variant} has no parameter {name!r}{hint}")
        if name in seen:
            raise FitError(f"free parameter {name!r} is listed twice")
        seen.add(name)
    if not free_names:
        raise FitError("no free parameters")
    return tuple(names.index(name) for name in free_names)


def _setup(
    recordings: Sequence[Recording],
    initial: ParameterSet,
    free_names: Sequence[str] | None,
    options: BaselineOptions,
) -> tuple[Model, tuple[str, ...], tuple[int, ...], np.ndarray, _Data]:
    """Check the inputs and prepare the data (every check runs before any solving)."""
    recordings = list(recordings)
    if not recordings:
        raise FitError("no recordings to fit")
    if not isinstance(initial, ParameterSet):
        raise FitError(f"initial must be a ParameterSet, got {type(initial).__name__}")
    model = build_model(initial.variant)
    free_names = (
        tuple(free_names) if free_names is not None else default_free_names(initial.variant)
    )
    free = _free_indices(model, free_names)
    p0 = model.parameter_vector(initial.values)
    for name, i in zip(free_names, free, strict=True):
        if not p0[i] > 0:
            raise FitError(
                f"free parameter {name} starts at {p0[i]}; log parameters need a value > 0"
            )
    data = _prepare(model, recordings, p0, options.rest_state)
    n_res = int(data.mask.sum())
    if n_res <= len(free):
        raise FitError(f"{n_res} valid samples cannot determine {len(free)} free parameters")
    return model, free_names, free, p0, data


def evaluation_timings(
    recordings: Sequence[Recording],
    initial: ParameterSet,
    free_names: Sequence[str] | None = None,
    options: BaselineOptions | None = None,
    repeats: int = 3,
) -> dict[str, float]:
    """Median wall time [s] of one residual evaluation and of one Jacobian by each method at
    ``initial`` (after a warm-up call, so compiling and function building are excluded)."""
    options = options or BaselineOptions()
    model, _, free, p0, data = _setup(recordings, initial, free_names, options)
    theta = np.zeros(len(free))
    timings = {}
    for label, method in (
        ("residuals", None),
        ("sensitivities", "sensitivities"),
        ("finite-differences", "finite-differences"),
    ):
        opts = replace(options, jacobian=method or options.jacobian)
        problem = _SingleShooting(model, data, p0, free, opts, None)
        call = problem.residuals if method is None else problem.jacobian
        call(theta)
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            call(theta)
            times.append(time.perf_counter() - t0)
        timings[label] = float(np.median(times))
    return timings


def fit_single_shooting(
    recordings: Sequence[Recording],
    initial: ParameterSet,
    free_names: Sequence[str] | None = None,
    options: BaselineOptions | None = None,
) -> BaselineResult:
    """Fit free parameters by single shooting with ``scipy.optimize.least_squares`` (trf).

    Parameters
    ----------
    recordings : experiments of one rig and sample rate, each starting at rest.
    initial : start values (and the values of fixed parameters).
    free_names : parameters to fit (default: ``default_free_names``, the fitter's default).
    options : solver options.

    Returns
    -------
    BaselineResult; ``success`` is False if the solver was capped, failed or ended at a bound.

    Raises
    ------
    FitError : empty or mixed recordings, unknown or duplicate free names, a free parameter
        that is not > 0 (log parameters), too few valid samples.
    """
    options = options or BaselineOptions()
    model, free_names, free, p0, data = _setup(recordings, initial, free_names, options)
    start = time.perf_counter()
    _substeps(model, free, options.compile_c)
    setup = time.perf_counter() - start
    start = time.perf_counter()
    deadline = None if options.max_time_s is None else start + options.max_time_s
    problem = _SingleShooting(model, data, p0, free, options, deadline)
    theta0 = np.zeros(len(free))
    bound = math.log(options.bound_factor)
    with _single_threaded_blas():
        try:
            solution = least_squares(
                problem.residuals,
                theta0,
                jac=problem.jacobian,
                bounds=(-bound, bound),
                method="trf",
                x_scale=options.x_scale,
                tr_solver=options.tr_solver,
                ftol=options.ftol,
                xtol=options.xtol,
                gtol=options.gtol,
                max_nfev=options.max_nfev,
                verbose=options.verbose,
            )
        except _TimeLimit:
            solution = None
    if solution is not None:
        theta, cost = solution.x, float(solution.cost)
        capped = solution.status == 0
        ok = solution.status > 0
        message = str(solution.message)
    else:
        cost, theta = problem.best
        capped, ok = True, False
        message = f"stopped at the time limit of {options.max_time_s} s (best point kept)"
    wall = time.perf_counter() - start
    at_bound = tuple(
        n for n, t in zip(free_names, theta, strict=True) if abs(t) > bound * (1 - 1e-6)
    )
    if at_bound:
        message += f"; ends at a bound: {', '.join(at_bound)}"
    p = problem.parameters(theta)
    estimates = {name: float(p[i]) for name, i in zip(free_names, free, strict=True)}
    parameters = initial.replace_values(**estimates)
    return BaselineResult(
        success=bool(ok and not capped),
        message=message,
        estimates=estimates,
        parameters=parameters,
        cost=cost,
        initial_cost=problem.initial_cost,
        nfev=problem.nfev,
        njev=problem.njev,
        wall_time_s=wall,
        setup_time_s=setup,
        capped=capped,
        at_bound=at_bound,
        n_residuals=int(data.mask.sum()),
        jacobian=options.jacobian,
        free_names=free_names,
    )
