"""Equation-error start: the parameters from a linear regression on differentiated data.

The models are linear in their parameters once multiplied by the mass matrix: Lagrange's
equations read M(p) qddot - Q(q, qdot, u, p) = 0 with every term (kinetic energy, spring
energy, viscous and Coulomb friction, motor torque g K_t / R u) linear in one parameter. With
velocities and accelerations estimated from the measured positions (Savitzky-Golay), each
sample gives n_q equations linear in p, solved as a bounded linear least-squares problem.

No integration is involved, so this costs milliseconds; the estimate is biased (noise in the
regressors, belt stretch from noisy lasers, smoothing), which is why it is only a start for
the output-error fit. It matters for robustness: output-error fits of this stiff, frictional
system from starts off by factors of 3 spend most of their iterations (and sometimes fail)
finding the basin that this regression lands in directly.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from hframe_id.fitting.dataset import state_outputs
from hframe_id.fitting.problem import FitProblem

#: Savitzky-Golay window [samples] and polynomial order for velocities and accelerations.
SG_WINDOW = 5
SG_WINDOW_LASER = 11
SG_ORDER = 3
#: An equation is used only while its coordinate moves faster than this many smoothing
#: velocities.
SPEED_FACTOR = 20.0
#: Every this many samples enter the regression (neighbours are strongly correlated anyway).
STRIDE = 2


def convolve_zero_padded(y: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The convolution of ``y`` with an odd number of ``weights``, centred, ``y`` padded with
    zeros: ``scipy.ndimage.convolve1d(y, weights, mode="constant")`` bit for bit.

    The same floating-point operations in the same order as SciPy's C loop (``NI_Correlate1D``):
    the flipped weights are tested for symmetry and antisymmetry within DBL_EPSILON (absolute),
    and such weights are applied to sums or differences of mirrored samples, outermost pair
    first; other weights sample by sample from the last. numpy's element-wise operations round
    like the C code's (no fused multiply-add on x86-64, the platform of the test).
    """
    w = np.asarray(weights, dtype=float)[::-1]  # a convolution correlates with flipped weights
    if w.size % 2 != 1:
        raise ValueError(f"convolve_zero_padded needs an odd number of weights, got {w.size}")
    half, n = w.size // 2, len(y)
    padded = np.concatenate([np.zeros(half), np.asarray(y, dtype=float), np.zeros(half)])

    def shifted(offset: int) -> np.ndarray:
        return padded[half + offset : half + offset + n]

    pairs = range(half, 0, -1)
    eps = np.finfo(float).eps
    if all(abs(w[half + k] - w[half - k]) <= eps for k in pairs):
        out = shifted(0) * w[half]
        for k in pairs:
            out = out + (shifted(-k) + shifted(k)) * w[half - k]
    elif all(abs(w[half + k] + w[half - k]) <= eps for k in pairs):
        out = shifted(0) * w[half]
        for k in pairs:
            out = out + (shifted(-k) - shifted(k)) * w[half - k]
    else:
        out = shifted(half) * w[2 * half]
        for j in range(-half, half):
            out = out + shifted(j) * w[half + j]
    return out


def savgol_derivative(y: np.ndarray, window: int, order: int, deriv: int, dt: float) -> np.ndarray:
    """Savitzky-Golay estimate of the ``deriv``-th derivative of ``y`` [unit / s^deriv]: the
    derivative at the centre of the least-squares polynomial of ``order`` through ``window``
    (odd) samples spaced ``dt`` [s]. Wrong at the first and last ``window // 2`` samples
    (zero padding): callers drop them.

    The same operations as ``scipy.signal.savgol_filter`` in its interior (coefficients by a
    minimum-norm least-squares solve on the flipped offsets, LAPACK's gelsd like
    ``scipy.linalg.lstsq``; ``convolve_zero_padded``), so equal to it bit for bit there,
    without importing SciPy: ``scipy.signal`` costs 1.2 s, ``scipy.linalg`` and
    ``scipy.ndimage`` 0.3 s, of every fit's start-up.
    """
    half = window // 2
    offsets = np.arange(half, -half - 1, -1, dtype=float)
    vander = offsets ** np.arange(order + 1, dtype=float).reshape(-1, 1)
    target = np.zeros(order + 1)
    target[deriv] = float(math.factorial(deriv)) / dt**deriv
    cond = np.finfo(float).eps * max(vander.shape)
    coefficients = np.linalg.lstsq(vander, target, rcond=cond)[0]
    return convolve_zero_padded(y, coefficients)


def _acceleration_function(problem: FitProblem) -> ca.Function:
    """(x, qddot, u, p) -> (qddot - qddot_model, d/dp) per coordinate."""
    model = problem.model
    nx, nq = model.n_states, model.n_states // 2
    x = ca.SX.sym("x", nx)
    a = ca.SX.sym("a", nq)
    u = ca.SX.sym("u", model.n_inputs)
    p = ca.SX.sym("p", len(model.parameters))
    e = a - model.dynamics(x, u, p, ca.DM(problem.smoothing))[nq:]
    # Dense, so that the mapped outputs fill numpy buffers directly (``residual``).
    return ca.Function("acceleration_error", [x, a, u, p], [e, ca.densify(ca.jacobian(e, p))])


def equation_error_start(
    problem: FitProblem,
    positions: list[np.ndarray],
    usable: list[np.ndarray],
    rigid: list[np.ndarray] | None = None,
    threads: int = 1,
) -> np.ndarray:
    """Log-parameters theta (free parameters, relative to the problem's start).

    Minimises sum_j sum_k ((qddot_jk - qddot_model_j(x_k, u_k, p)) / s_j)^2 over log p
    within the bounds, with s_j the spread of equation j's residuals (updated twice). In
    acceleration form the equations are not homogeneous in p (the motor constants are
    fixed), so the regression cannot shrink all parameters together.

    Parameters
    ----------
    positions : per experiment, (N, n_q) coordinates (measured, unmeasured ones filled).
    usable : per experiment, (N,) samples whose positions are all measured or reliably
        filled.
    rigid : per experiment, (N, n_q) belt-free motion fitted to the measurements (dominated
        by the encoders): differentiated for velocities and accelerations, because laser
        noise (5 um) differentiated twice at 1 kHz swamps the end effector's acceleration.
        The positions themselves (spring stretches) come from ``positions``.
    threads : worker threads evaluating the equations (a fit's transcription's,
        ``TranscriptionOptions.threads``).
    """
    model = problem.model
    nq = model.n_states // 2
    dt = problem.sample_period_s
    fn = _acceleration_function(problem)
    p0 = problem.p_initial
    free = list(problem.free)
    vs = np.array(
        [problem.smoothing[0] if c.unit == "m" else problem.smoothing[1] for c in model.coordinates]
    )
    # Only coordinates a sensor measures, by their position or their rate (a tachometer's,
    # integrated into ``positions``), have equations (an unmeasured one, like the idler of
    # the one-axis drive, is only filled in as belt-free motion: no dynamics to regress).
    index = state_outputs(model)
    measured = np.zeros(nq, dtype=bool)
    measured[index[index >= 0] % nq] = True
    # Lasers (positions in m) are too noisy to differentiate over a few samples.
    windows = [SG_WINDOW_LASER if c.unit == "m" else SG_WINDOW for c in model.coordinates]
    data = []
    for exp, q, ok in zip(problem.experiments, positions, usable, strict=True):
        n = q.shape[0]
        if n < max(windows) + 2:
            continue
        qd = np.empty_like(q)
        qdd = np.empty_like(q)
        for j, win in enumerate(windows):
            qd[:, j] = savgol_derivative(q[:, j], win, SG_ORDER, 1, dt)
            qdd[:, j] = savgol_derivative(q[:, j], win, SG_ORDER, 2, dt)
        keep = ok.copy()
        half = max(windows) // 2 + 1
        keep[:half] = False
        keep[n - half :] = False
        # Derivative estimates straddling a voltage step are wrong (the acceleration jumps).
        for k in np.flatnonzero(np.any(np.diff(exp.inputs, axis=0) != 0, axis=1)):
            keep[max(k - half, 0) : k + half + 2] = False
        idx = np.flatnonzero(keep)[::STRIDE]
        if idx.size:
            # Equation j only where coordinate j moves clearly: near zero speed the Coulomb
            # term's sign is set by noise, which biases the friction levels towards zero.
            moving = (np.abs(qd[idx]) > SPEED_FACTOR * vs) & measured[None, :]
            data.append((np.hstack([q[idx], qd[idx]]).T, qdd[idx].T, exp.inputs[idx].T, moving.T))
    if not data:
        return np.zeros(len(free))
    xs = np.hstack([d[0] for d in data])
    acc = np.hstack([d[1] for d in data])
    us = np.hstack([d[2] for d in data])
    mask = np.hstack([d[3] for d in data]).astype(float)  # (nq, n)
    n = xs.shape[1]
    mapped = fn.map(n, "thread", threads)
    # Inputs and outputs bound once to numpy arrays (column-major: an (r, c) matrix is a
    # C-order (c, r) array): converting DMs costs twice the evaluation itself.
    buffer, run = mapped.buffer()
    args = [np.ascontiguousarray(v.T) for v in (xs, acc, us)] + [np.empty((n, len(p0)))]
    outs = [np.empty((n, nq)), np.empty((n * len(p0), nq))]
    for i, array in enumerate(args):
        buffer.set_arg(i, memoryview(array))
    for i, array in enumerate(outs):
        buffer.set_res(i, memoryview(array))
    scale = np.ones(nq)

    cache: dict = {}

    def residual(theta):
        key = theta.tobytes()
        if key not in cache:
            cache.clear()
            p = problem.parameters(theta)
            args[3][:] = p
            run()
            e = np.ascontiguousarray(outs[0].T) * mask  # (nq, n)
            jac = np.ascontiguousarray(outs[1].reshape(n, -1, nq).transpose(2, 0, 1))
            jac = jac[:, :, free] * problem.parameter_slopes(p) * mask[:, :, None]
            cache[key] = (e, jac)
        e, jac = cache[key]
        return (e / scale[:, None]).ravel(), (jac / scale[:, None, None]).reshape(nq * n, -1)

    theta = np.zeros(len(free))
    for _ in range(2):
        e, _ = residual(theta)
        e = e.reshape(nq, n) * scale[:, None]
        for j in range(nq):
            used = np.abs(e[j][mask[j] > 0])
            # Robust spread (median absolute value): the residuals have heavy tails.
            scale[j] = max(1.4826 * float(np.median(used)) if used.size else 1.0, 1e-300)
        cache.clear()
        theta = _robust_gauss_newton(residual, theta, problem.theta_lower, problem.theta_upper)
    return theta


def _robust_cost(e: np.ndarray) -> float:
    """Soft-L1 (pseudo-Huber) cost: quadratic for |e| < 1, linear beyond (outliers near
    stops and reversals, where the differentiated data are worst)."""
    return float(np.sum(2 * (np.sqrt(1 + e**2) - 1)))


def _robust_gauss_newton(residual, theta, lower, upper, iterations: int = 40) -> np.ndarray:
    """Levenberg-Marquardt with iteratively reweighted (soft-L1) residuals, in the bounds.

    A 16-parameter problem: the normal equations are tiny, so this beats SciPy's trust-region
    reflective method (an SVD of the whole Jacobian per iteration) by an order of magnitude.
    """
    lam = 1e-3
    e, jac = residual(theta)
    cost = _robust_cost(e)
    for _ in range(iterations):
        w = 1 / np.sqrt(np.sqrt(1 + e**2))  # sqrt of the IRLS weight 1 / sqrt(1 + e^2)
        jw = jac * w[:, None]
        h = jw.T @ jw
        g = jw.T @ (e * w)
        improved = False
        for _ in range(20):
            step = -np.linalg.solve(h + lam * np.diag(np.maximum(np.diag(h), 1e-12)), g)
            trial = np.clip(theta + step, lower, upper)
            e_new, jac_new = residual(trial)
            cost_new = _robust_cost(e_new)
            if np.isfinite(cost_new) and cost_new < cost:
                improved = True
                break
            lam *= 10.0
        if not improved:
            break
        change = float(np.max(np.abs(trial - theta)))
        theta, e, jac, cost = trial, e_new, jac_new, cost_new
        lam = max(lam / 10.0, 1e-9)
        if change < 1e-6:
            break
    return theta
