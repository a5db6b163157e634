"""RK4 substeps per sample of the shooting windows at one point, and when a point is refused.

The smoothed Coulomb law makes the dynamics stiff only near zero velocity: at rest the
Jacobian's spectral radius is about tau_c / (v_s J) (~4.5e4 1/s at Table 4.2), in motion the
belt modes' ~330 1/s. ``plan_substeps`` gives the two counts (``substeps_for_radius``: at
most ``max_substeps`` for the safety margin, never fewer than stability needs) and, per
velocity, the speed below which a window needs the stiff count. A point where stability
alone needs more than ``max_substeps`` is refused (``MultipleShooting.evaluate``): its
integration would cost that count in every stiff window, and a capped one would be
unstable (docs/studies/2026-11-27-fleet-fit-crawl-and-fleet-check.md).
"""

from __future__ import annotations

import math
from functools import lru_cache

import casadi as ca
import numpy as np

from hframe_id.fitting.link_options import TranscriptionOptions
from hframe_id.models import Model
from hframe_id.simulation.integrators import (
    MIN_SUBSTEPS,
    RK4_STABILITY_LIMIT,
    substeps_for_radius,
)


def coordinate_smoothing(model: Model, smoothing) -> np.ndarray:
    """(n_q,) each coordinate's smoothing velocity: ``smoothing`` = (linear [m/s], angular
    [rad/s])."""
    return np.array([smoothing[0] if c.unit == "m" else smoothing[1] for c in model.coordinates])


@lru_cache(maxsize=32)
def _state_jacobian(model: Model) -> ca.Function:
    """A(x, p, s) = df/dx at inputs 0 (built once per model)."""
    x = ca.SX.sym("x", model.n_states)
    p = ca.SX.sym("p", len(model.parameters))
    s = ca.SX.sym("s", 2)
    f = model.dynamics(x, ca.DM.zeros(model.n_inputs), p, s)
    return ca.Function("state_jacobian", [x, p, s], [ca.jacobian(f, x)])


def rest_and_moving_jacobians(model: Model, p: np.ndarray, smoothing):
    """(df/dx at rest, df/dx at 100 smoothing velocities, each coordinate's smoothing
    velocity) at all parameters ``p`` (SI, model order): what ``plan_substeps`` and
    ``coulomb_rates`` read."""
    jac = _state_jacobian(model)
    vs = coordinate_smoothing(model, smoothing)
    moving = np.concatenate([np.zeros(len(vs)), 100.0 * vs])
    s = ca.DM(smoothing)
    at = lambda x: np.array(jac(x, p, s))  # noqa: E731
    return at(np.zeros(model.n_states)), at(moving), vs


def coulomb_rates(a_rest: np.ndarray, a_moving: np.ndarray) -> np.ndarray:
    """(n_q,) each velocity's Coulomb rate at rest [1/s] from the Jacobians at rest and in
    motion (``rest_and_moving_jacobians``): its own rate at rest less that in motion, where
    the smoothed Coulomb slope has decayed by sech^2(100) to nothing."""
    nq = a_rest.shape[0] // 2
    return np.abs(np.diag(a_rest)[nq:] - np.diag(a_moving)[nq:])


def plan_substeps(
    a_rest: np.ndarray,
    a_moving: np.ndarray,
    smoothing_velocity: np.ndarray,
    dt: float,
    options: TranscriptionOptions,
) -> dict:
    """The plan from the dynamics' Jacobians df/dx at rest and at 100 smoothing velocities
    (``a_rest``, ``a_moving``, (n_x, n_x) [1/s]), each velocity state's smoothing velocity
    [m/s or rad/s] and the sample period ``dt`` [s]: {"fast", "stiff": substeps per sample,
    "threshold": (n_q,) speeds below which a window needs "stiff" (0: never), "refused":
    whether stability at rest needs more than ``options.max_substeps``}."""
    nq = len(smoothing_velocity)
    safety, cap = options.substep_safety, options.max_substeps
    radius_moving = float(np.max(np.abs(np.linalg.eigvals(a_moving))))
    radius_rest = float(np.max(np.abs(np.linalg.eigvals(a_rest))))
    # One rule for both counts. stiff: the simulators' count (``stable_substeps``: the same
    # Jacobian at rest, bitwise), never fewer than fast, the fit's max_substeps as cap
    # instead of 400. fast: the rule at the moving Jacobian, a different quantity (the
    # Coulomb slope there has decayed by sech^2(100) to nothing).
    fast = substeps_for_radius(radius_moving, dt, safety, MIN_SUBSTEPS, cap)
    stiff = substeps_for_radius(radius_rest, dt, safety, fast, cap)
    # Coulomb part of each velocity's own rate: lambda_j sech^2(v / v_s).
    lam = coulomb_rates(a_rest, a_moving)
    limit = RK4_STABILITY_LIMIT / safety
    threshold = np.zeros(nq)
    for j in range(nq):
        ratio = 0.5 * limit / max(lam[j] * dt / fast, 1e-300)  # factor 0.5: margin
        if ratio < 1:
            threshold[j] = smoothing_velocity[j] * math.acosh(1 / math.sqrt(ratio))
    return {"fast": fast, "stiff": stiff, "threshold": threshold, "refused": stiff > cap}


def stopped_message(stiff_substeps: int, max_substeps: int) -> str:
    """Why a stage can compute no step at a point whose stiff count is ``stiff_substeps``:
    refused for its stiffness (above ``max_substeps``), or sensitivities that overflow."""
    if stiff_substeps > max_substeps:
        return (
            f"stopped: at these parameters the friction at rest is so stiff that a stable "
            f"RK4 integration needs {stiff_substeps} substeps per sample, more than "
            f"max_substeps {max_substeps}"
        )
    return (
        "stopped: the model's sensitivities overflow at these parameters (so stiff or "
        "unstable there that no step can be computed)"
    )
