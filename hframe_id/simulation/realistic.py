"""Dynamics of the realistic sim-rig plant: stick-slip friction with a Stribeck curve and an
amplifier current limit, on any model variant (docs/realistic-rig.md).

The model's own equations (springs, inertia, position-dependent belt stiffness if the model was
built with it) give every generalized force except friction and the motors; this module adds

- the motor torque through a current-limited amplifier (docs/realistic-rig.md, eq. A1-A2):
  i = clip((g V - K_e phidot) / R, -I_max, I_max), tau = K_t i; with I_max = inf this is
  eq. 2.4 exactly;
- on every friction-bearing coordinate Table 2.2's stick-slip logic with breakaway force
  F_s = rho F_c and a Stribeck curve (eq. S1, ``friction.stick_slip_force``); a stuck
  coordinate is brought to rest with time constant tau_stick (eq. S2: F_f = F_a + m v /
  tau_stick), where Table 2.2 lets it creep at whatever speed inside the band it stuck with.

The dynamics are a CasADi function (x, u, p, c) -> xdot with c the plant constants
(``CONSTANTS``), integrated by the same fixed-step RK4 as everything else.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from hframe_id.models import Model
from hframe_id.simulation.compiled import evaluate
from hframe_id.simulation.friction import friction_sites, stick_slip_force, stick_slip_substeps
from hframe_id.simulation.integrators import rk4_function

#: Order of the plant constants vector c of ``realistic_dynamics``.
CONSTANTS = (
    "stick_band_linear [m/s]",
    "stick_band_angular [rad/s]",
    "static_to_coulomb_ratio [-]",
    "stribeck_velocity_linear [m/s]",
    "stribeck_velocity_angular [rad/s]",
    "current_limit [A]",
    "stick_time_constant [s]",
)


@dataclass(frozen=True)
class PlantConstants:
    """Friction-law and amplifier constants of a realistic plant (SI).

    Attributes
    ----------
    stick_band_linear_m_per_s, stick_band_angular_rad_per_s : Table 2.2's stick band.
    static_to_coulomb_ratio : rho = F_s / F_c >= 1 (1: no Stribeck peak, Table 2.2 exactly).
    stribeck_velocity_linear_m_per_s, stribeck_velocity_angular_rad_per_s : v_St.
    current_limit_a : amplifier current limit I_max [A] (``math.inf``: none).
    stick_time_constant_s : tau_stick, how fast a stuck coordinate comes to rest [s].
    """

    stick_band_linear_m_per_s: float
    stick_band_angular_rad_per_s: float
    static_to_coulomb_ratio: float
    stribeck_velocity_linear_m_per_s: float
    stribeck_velocity_angular_rad_per_s: float
    current_limit_a: float
    stick_time_constant_s: float

    def vector(self) -> np.ndarray:
        """The c input of ``realistic_dynamics``, in ``CONSTANTS`` order."""
        return np.array(
            [
                self.stick_band_linear_m_per_s,
                self.stick_band_angular_rad_per_s,
                self.static_to_coulomb_ratio,
                self.stribeck_velocity_linear_m_per_s,
                self.stribeck_velocity_angular_rad_per_s,
                self.current_limit_a,
                self.stick_time_constant_s,
            ]
        )


@lru_cache(maxsize=32)
def motor_sites(model: Model) -> tuple[tuple[int, int], ...]:
    """Per input: (index in q of the coordinate its motor drives, index in p of its gain g)."""
    x = ca.SX.sym("x", model.n_states)
    u = ca.SX.sym("u", model.n_inputs)
    p = ca.SX.sym("p", len(model.parameters))
    rows, columns = ca.jacobian(model.actuation(x, u, p), u).sparsity().get_triplet()
    names = list(model.parameter_names)
    return tuple((rows[columns.index(i)], names.index(f"g_{i + 1}")) for i in range(model.n_inputs))


def motor_current(
    voltage: ca.SX, rate: ca.SX, gain: ca.SX, k_e: ca.SX, resistance: ca.SX, limit: ca.SX
) -> ca.SX:
    """Armature current [A] behind a current-limited amplifier (eq. A1):
    i = clip((g V - K_e phidot) / R, -I_max, I_max)."""
    return ca.fmin(ca.fmax((gain * voltage - k_e * rate) / resistance, -limit), limit)


@lru_cache(maxsize=32)
def realistic_dynamics(model: Model) -> ca.Function:
    """xdot = f(x, u, p, c): the model with current-limited motors and Stribeck stick-slip."""
    x = ca.SX.sym("x", model.n_states)
    u = ca.SX.sym("u", model.n_inputs)
    p = ca.SX.sym("p", len(model.parameters))
    c = ca.SX.sym("c", len(CONSTANTS))
    band_linear, band_angular, ratio, stribeck_linear, stribeck_angular, limit, tau = ca.vertsplit(
        c
    )
    names = list(model.parameter_names)
    sites = friction_sites(model)
    n_q = model.n_states // 2
    mask = np.ones(len(model.parameters))
    for site in sites:
        mask[[site.viscous, site.coulomb]] = 0.0
    mask[names.index("K_t")] = 0.0  # motor torque enters below, through the amplifier
    free = model.dynamics(x, u, p * ca.DM(mask), ca.DM([1.0, 1.0]))
    mass = model.mass(p)
    active = ca.vertsplit(ca.mtimes(mass, free[n_q:]))  # springs only [N or N m]
    k_t, k_e, resistance = (p[names.index(n)] for n in ("K_t", "K_e", "R"))
    for i, (j, gain) in enumerate(motor_sites(model)):
        current = motor_current(u[i], x[n_q + j], p[gain], k_e, resistance, limit)
        active[j] = active[j] + k_t * current  # eq. A2
    friction = [ca.SX(0)] * n_q
    for site in sites:
        j = site.coordinate
        coulomb = p[site.coulomb]
        friction[j] = stick_slip_force(
            x[n_q + j],
            active[j],
            p[site.viscous],
            coulomb,
            ratio * coulomb,
            band_linear if site.linear else band_angular,
            stribeck_linear if site.linear else stribeck_angular,
            mass[j, j] * x[n_q + j] / tau,  # eq. S2; M is diagonal in every variant
        )
    qddot = ca.solve(mass, ca.vertcat(*active) - ca.vertcat(*friction))
    return ca.Function(
        "realistic_dynamics",
        [x, u, p, c],
        [ca.vertcat(x[n_q:], qddot)],
        ["x", "u", "p", "s"],
        ["xdot"],
    )


def realistic_substeps(
    model: Model, p: np.ndarray, dt: float, constants: PlantConstants, refine: int = 1
) -> int:
    """RK4 substeps per sample: ``stick_slip_substeps`` with the breakaway level F_s = rho F_c
    (the largest friction deceleration), and at least 2 substeps per tau_stick (the stuck
    decay rate 1 / tau_stick times h <= 0.5, well inside RK4's 2.785); times ``refine``
    (reference runs)."""
    p = np.array(p, dtype=float)
    for site in friction_sites(model):
        p[site.coulomb] *= constants.static_to_coulomb_ratio
    band = (constants.stick_band_linear_m_per_s, constants.stick_band_angular_rad_per_s)
    needed = max(
        stick_slip_substeps(model, p, dt, band), math.ceil(2 * dt / constants.stick_time_constant_s)
    )
    return refine * needed


@lru_cache(maxsize=32)
def realistic_step(model: Model, n_substeps: int, dt: float) -> ca.Function:
    """One held sample of the realistic plant: F(x, u, p, c) -> x_next."""
    return rk4_function(realistic_dynamics(model), n_substeps, dt)


@lru_cache(maxsize=32)
def _trajectory(model: Model, n_substeps: int, dt: float, n_samples: int) -> ca.Function:
    """X = F(x0, U, p, c): the states after each of ``n_samples`` held-input samples."""
    step = realistic_step(model, n_substeps, dt)
    x0, u = ca.MX.sym("x0", model.n_states), ca.MX.sym("u", model.n_inputs, n_samples)
    p, c = ca.MX.sym("p", step.size1_in(2)), ca.MX.sym("c", len(CONSTANTS))
    states = step.mapaccum("trajectory", n_samples)(x0, u, p, c)
    return ca.Function("realistic_trajectory", [x0, u, p, c], [states])


def simulate_realistic(
    model: Model,
    p: np.ndarray,
    constants: PlantConstants,
    inputs: np.ndarray,
    dt: float,
    n_substeps: int,
) -> np.ndarray:
    """(N + 1, n_x) states at t_0 .. t_N from rest, input row k held over [t_k, t_k+1]."""
    inputs = np.atleast_2d(np.asarray(inputs, dtype=float))
    x0 = np.zeros(model.n_states)
    horizon = _trajectory(model, int(n_substeps), float(dt), inputs.shape[0])
    (states,) = evaluate(horizon, [x0, inputs, np.asarray(p, float), constants.vector()])
    return np.vstack([x0, states])
