"""Fixed-step RK4 with substeps over one zero-order-hold sample, shared by simulator and fitter.

The one place of the RK4 stages (``rk4_substep``): the simulators, the sim rig and the closed
loop build their per-sample step from it with a numeric substep length, the fitter's kernels
(``hframe_id.fitting.kernel``) with a symbolic one. The stages are the same operations in the
same order either way, so simulator and fitter states agree bit for bit on the same inputs
(tests/simulation/test_simulation_integrator.py).

Why fixed-step RK4: the input is zero-order held at the sample time (1 ms, section 5.3), so
each sample is one smooth initial-value problem; a fixed number of RK4 substeps gives a
CasADi expression graph that can be compiled once, mapped over thousands of samples and
differentiated exactly (the fitter needs its sensitivities).

Stability: the smoothed Coulomb law F_c tanh(v / v_s) has slope F_c / v_s at v = 0, which
gives a fast real eigenvalue of about tau_c / (v_s J_M) (~4.5e4 1/s at the thesis's values).
Explicit RK4 is stable for |lambda| h < 2.785, so the substep count must follow the current
parameters: ``stable_substeps`` bounds the spectral radius of the Jacobian at rest (where the
tanh slope is largest) and adds a safety factor.

Accuracy (tests/simulation/test_simulation_integrator.py, docs/friction.md): against scipy's
Radau with rtol 1e-10 on 2-10 V steps, reversals and stops with Coulomb friction, the default
substeps keep every position within 2 um and every velocity within 0.5 mm/s for all three
variants (angles as belt length r phi; measured 0.3-0.7 um and 0.03-0.1 mm/s). The error is set
by how well the substeps resolve the tanh knee, not by RK4's order."""

from __future__ import annotations

import math
from functools import lru_cache

import casadi as ca
import numpy as np

from hframe_id.errors import ModelError
from hframe_id.models import Model, build_model
from hframe_id.simulation import MAX_SUBSTEPS

#: Real-axis stability limit of classical RK4: |lambda h| <= 2.785.
RK4_STABILITY_LIMIT = 2.785
#: Fewest substeps per sample: keeps the belt modes (|lambda| ~ 330 1/s) accurate to ~1e-8.
MIN_SUBSTEPS = 4


def rk4_step(model: Model, n_substeps: int, dt: float) -> ca.Function:
    """One sample of length ``dt`` [s] with the input held: F(x, u, p, s) -> x_next.

    Built from SX so the whole step is one flat expression graph (fast to evaluate, map and
    differentiate).
    """
    return rk4_function(model.dynamics, n_substeps, dt)


def rk4_function(dynamics: ca.Function, n_substeps: int, dt: float) -> ca.Function:
    """``n_substeps`` classical RK4 steps of any (x, u, p, s) -> xdot over one held sample."""
    if n_substeps < 1:
        raise ValueError(f"n_substeps must be >= 1, got {n_substeps}")
    if not dt > 0:
        raise ValueError(f"dt must be > 0 s, got {dt}")
    x = ca.SX.sym("x", dynamics.size1_in(0))
    u = ca.SX.sym("u", dynamics.size1_in(1))
    p = ca.SX.sym("p", dynamics.size1_in(2))
    s = ca.SX.sym("s", dynamics.size1_in(3))
    return ca.Function(
        "rk4_step", [x, u, p, s], [rk4_expression(dynamics, x, u, p, s, n_substeps, dt)],
        ["x", "u", "p", "s"], ["x_next"],
    )  # fmt: skip


def rk4_expression(
    dynamics: ca.Function,
    x: ca.SX,
    u: ca.SX,
    p: ca.SX,
    s: ca.SX,
    n_substeps: int,
    dt: float,
) -> ca.SX:
    """State after ``dt`` [s] from ``x`` under held ``u``: ``n_substeps`` RK4 steps, as SX."""
    h = dt / n_substeps
    xk = x
    for _ in range(n_substeps):
        xk = rk4_substep(dynamics, xk, u, p, s, h)
    return xk


def rk4_substep(
    dynamics: ca.Function,
    x: ca.SX,
    u: ca.SX,
    p: ca.SX,
    s: ca.SX,
    h: float | ca.SX,
) -> ca.SX:
    """State after one classical RK4 step of length ``h`` [s] from ``x`` under held ``u``.

    Parameters
    ----------
    dynamics : (x, u, p, s) -> xdot.
    x, u, p, s : state, held input [V], parameters (SI) and Coulomb smoothing velocities
        [m/s, rad/s], as SX.
    h : substep length [s]: a float (the simulators: ``dt / n_substeps``) or an SX symbol
        (the fitter's kernels, which take it as an input).

    Returns
    -------
    The state after the step, as SX.

    Notes
    -----
    With the same value of ``h`` both forms compute the same IEEE operations in the same order
    (``h / 2`` and ``h / 6`` are rounded once, by Python or at run time), so they agree bit
    for bit. Reordering any term here changes the generated C and hence the cache key of every
    compiled kernel (``hframe_id.native.cache_key``).
    """
    k1 = dynamics(x, u, p, s)
    k2 = dynamics(x + h / 2 * k1, u, p, s)
    k3 = dynamics(x + h / 2 * k2, u, p, s)
    k4 = dynamics(x + h * k3, u, p, s)
    return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


@lru_cache(maxsize=32)
def _jacobian_at_rest(model: Model) -> ca.Function:
    """A(p, s) = df/dx at x = 0, u = 0 (built once per model)."""
    x = ca.SX.sym("x", model.n_states)
    u = ca.SX.sym("u", model.n_inputs)
    p = ca.SX.sym("p", len(model.parameters))
    s = ca.SX.sym("s", 2)
    jacobian = ca.Function("jacobian", [x, u, p, s], [ca.jacobian(model.dynamics(x, u, p, s), x)])
    at_rest = jacobian(ca.DM.zeros(model.n_states), ca.DM.zeros(model.n_inputs), p, s)
    return ca.Function("jacobian_at_rest", [p, s], [at_rest])


def spectral_radius_at_rest(model: Model, p: np.ndarray, s: tuple[float, float]) -> float:
    """Largest |eigenvalue| [1/s] of df/dx at rest, smoothed Coulomb included."""
    a = np.array(_jacobian_at_rest(model)(np.asarray(p, dtype=float), ca.DM(s)))
    return float(np.max(np.abs(np.linalg.eigvals(a))))


def stable_substeps(
    model: Model,
    p: np.ndarray,
    dt: float,
    s: tuple[float, float] | None = None,
    safety: float = 1.5,
    minimum: int = MIN_SUBSTEPS,
    cap: int = 400,
) -> int:
    """RK4 substeps per sample so that |lambda_max| h <= 2.785 / safety, within [minimum, cap]
    and never fewer than the stability count (``substeps_for_radius``).

    lambda_max is the spectral radius of df/dx at rest (``spectral_radius_at_rest``), where
    the smoothed Coulomb slope is steepest. ``safety`` 1.5 keeps the fast friction mode well
    damped (not just bounded); ``minimum`` 4 keeps the oscillatory belt modes
    (|lambda| ~ 330 1/s) accurate to ~1e-8 per sample. The simulators and the sim rig choose
    their substeps here; the fitter's count for stiff windows (``MultipleShooting.substep_plan``)
    is this number with the fit's safety and cap (tests/simulation/test_simulation_integrator.py).
    """
    s = tuple(float(v) for v in (model.options.smoothing if s is None else s))
    p = np.ascontiguousarray(p, dtype=float)
    radius = _cached_radius(model, p.tobytes(), s)
    if not radius * dt / RK4_STABILITY_LIMIT <= MAX_SUBSTEPS:  # NaN too
        from hframe_id.parameters.files import most_extreme

        values = dict(zip((spec.name for spec in model.parameters), p.tolist(), strict=True))
        raise ModelError(
            f"{model.variant} is too stiff to simulate at these values: its fastest mode at "
            f"rest ({radius:.3g} 1/s) needs more than {MAX_SUBSTEPS:,} RK4 substeps per "
            f"sample of {dt:g} s; the most extreme is {most_extreme(values)}"
        )
    return substeps_for_radius(radius, dt, safety, minimum, cap)


def check_simulable(params, sample_period_s: float, source: str) -> None:
    """Refuse a parameter file (``params``, a ``ParameterSet`` read from ``source``) whose
    values are too stiff to simulate at ``sample_period_s`` [s] (``stable_substeps``): one
    ``ModelError`` naming the source and the most extreme value. The commands that start
    from a file rather than simulate it first (a fit's start and known points, a design's
    nominal values) check it before any work: they were least-squares or eigenvalue
    tracebacks deep in the fitter (a pulley radius of 1e300 m), or a misleading refusal."""
    model = build_model(params.variant)
    try:
        stable_substeps(model, model.parameter_vector(params.values), sample_period_s)
    except ModelError as err:
        raise ModelError(f"{source}: {err}") from None


def substeps_for_radius(
    radius: float, dt: float, safety: float = 1.5, minimum: int = MIN_SUBSTEPS, cap: int = 400
) -> int:
    """Fewest RK4 substeps per sample of ``dt`` [s] with |lambda| h <= 2.785 / ``safety`` for
    a spectral radius ``radius`` [1/s], within [``minimum``, ``cap``], and never fewer than
    ``stability_substeps``: the cap limits the safety margin, not stability. (A cap below
    the stability count made the linearised RK4 step grow by 1e100 over a window at a fit's
    point: sensitivities of 1e144 and a "converged" fit with standard errors of 1e-126,
    docs/studies/2026-11-27-fleet-fit-crawl-and-fleet-check.md.)"""
    needed = math.ceil(radius * dt * safety / RK4_STABILITY_LIMIT)
    return int(max(min(max(needed, minimum), cap), stability_substeps(radius, dt)))


def stability_substeps(radius: float, dt: float) -> int:
    """Fewest RK4 substeps per sample of ``dt`` [s] with |lambda| h <= 2.785 for a spectral
    radius ``radius`` [1/s]: below it the step amplifies the fastest mode."""
    return max(1, math.ceil(radius * dt / RK4_STABILITY_LIMIT))


@lru_cache(maxsize=256)
def _cached_radius(model: Model, p_bytes: bytes, s: tuple[float, float]) -> float:
    """``spectral_radius_at_rest`` memoized (simulators ask again for every run); infinite
    where the Jacobian overflows (a pulley radius of 1e300 m), which ``stable_substeps``
    refuses as too stiff (it was a LinAlgError traceback)."""
    try:
        return spectral_radius_at_rest(model, np.frombuffer(p_bytes, dtype=float), s)
    except np.linalg.LinAlgError:
        return math.inf
