"""Friction laws for simulation: the smoothed Coulomb model, the thesis's stick-slip logic, and
the discontinuous sign law of the benchmarks.

Three ways to compute the friction force F_f on each friction-bearing coordinate
(docs/friction.md compares them):

``smooth`` (the model's own law, used by identification as well)
    F_f = b v + F_c tanh(v / v_s), v_s a small smoothing velocity (model option). Smooth, so it
    can be differentiated and integrated by RK4, but stiff near v = 0 (slope F_c / v_s).

``stick-slip`` (Table 2.2, simulation only)
    The Embedded Matlab function of the thesis, per coordinate, with the active force F_a (all
    generalized forces on the coordinate except friction: springs, motor torque with back-EMF):

        F_tmp = b v + sign(v) F_c
        if |v| <= band and |F_a| <= F_c:  F_f = F_a      (friction cancels the active force)
        else:                              F_f = F_tmp

    Friction is passive: inside the velocity band it can hold the coordinate but not reverse its
    motion. Not differentiable (if_else), but not stiff either.

``sign`` (simulation only)
    F_f = b v + F_c sign(v), sign(0) = 0: Simulink's "Coulomb & Viscous Friction" block, the law
    the EMPS benchmark simulates its closed loop with (Simulink_EMPS_Rigide.slx) and its
    inverse model regresses on (Script_IDIM_LS.m). No band, no smoothing: a coordinate whose
    active force is below F_c chatters about v = 0 by F_c / m h per integrator step h, as the
    benchmark's own simulation does (ode45 without zero-crossing detection).

All three are CasADi functions (x, u, p, s) -> xdot with the same signature as ``Model.dynamics``;
for ``stick-slip`` the last input is the velocity band (linear [m/s], angular [rad/s]) instead of
the smoothing velocities.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from hframe_id.errors import OptionError
from hframe_id.models import Model
from hframe_id.simulation.integrators import stable_substeps

FRICTION_MODELS = ("smooth", "stick-slip", "sign")

#: Table 2.2's band: the motor pulley counts as stuck for |phidot| <= 0.01 rad/s.
STICK_BAND_ANGULAR_RAD_PER_S = 0.01
#: The thesis prints the code for the motor pulley only ("similar code" on the linear axes). The
#: same belt speed on a linear axis is 0.01 rad/s x r = 1.94e-4 m/s at r = 19.4 mm; this default
#: is an assumption, not a thesis value.
STICK_BAND_LINEAR_M_PER_S = 0.01 * 0.0194


@dataclass(frozen=True)
class FrictionOptions:
    """Which friction law the simulator uses.

    Attributes
    ----------
    model : ``"smooth"`` (tanh, the model's own), ``"stick-slip"`` (Table 2.2) or ``"sign"``
        (discontinuous Coulomb, the benchmarks' law).
    band_linear_m_per_s, band_angular_rad_per_s : stick-slip velocity band (ignored by the
        other laws).
    """

    model: str = "smooth"
    band_linear_m_per_s: float = STICK_BAND_LINEAR_M_PER_S
    band_angular_rad_per_s: float = STICK_BAND_ANGULAR_RAD_PER_S

    def __post_init__(self) -> None:
        if self.model not in FRICTION_MODELS:
            raise OptionError(
                f"unknown friction model {self.model!r}; valid: {', '.join(FRICTION_MODELS)}"
            )
        for name in ("band_linear_m_per_s", "band_angular_rad_per_s"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise OptionError(f"stick-slip {name} must be > 0, got {value!r}")

    @property
    def band(self) -> tuple[float, float]:
        """The stick-slip band: (linear [m/s], angular [rad/s]) velocities."""
        return (self.band_linear_m_per_s, self.band_angular_rad_per_s)

    def shape(self, model: Model) -> tuple[float, float]:
        """The ``s`` input of the dynamics: smoothing velocities or the stick-slip band."""
        return model.options.smoothing if self.model == "smooth" else self.band


@dataclass(frozen=True)
class FrictionSite:
    """One friction-bearing coordinate: its index in q and its parameters' indices in p."""

    coordinate: int
    viscous: int
    coulomb: int
    linear: bool


@lru_cache(maxsize=32)
def friction_sites(model: Model) -> tuple[FrictionSite, ...]:
    """Where friction acts in ``model`` (from its declaration's friction-bearing coordinates).
    The stick-slip law (Table 2.2) has its own breakaway level: a declared Stribeck curve is
    an error here, not silently dropped."""
    curved = [f.coordinate for f in model.frictions if f.static is not None]
    if curved:
        raise OptionError(
            f"stick-slip friction needs viscous + Coulomb friction; model {model.variant} "
            f"declares a Stribeck curve on {', '.join(curved)} (use the smooth friction)"
        )
    names = [c.name for c in model.coordinates]
    parameters = list(model.parameter_names)
    return tuple(
        FrictionSite(
            names.index(f.coordinate),
            parameters.index(f.viscous),
            parameters.index(f.coulomb),
            model.coordinates[names.index(f.coordinate)].unit == "m",
        )
        for f in model.frictions
    )


def stick_slip_force(
    rate: ca.SX,
    active: ca.SX,
    viscous: ca.SX,
    coulomb: ca.SX,
    static: ca.SX,
    width: ca.SX,
    stribeck_velocity: ca.SX | float = 1.0,
    hold: ca.SX | float = 0.0,
) -> ca.SX:
    """Friction force [N or N m] on one coordinate: Table 2.2's logic with a Stribeck curve.

    Stuck (``|v| <= width`` and ``|F_a| <= F_s``): F_f = F_a + hold. Slipping:

        F_f = b v + sign(v) (F_c + (F_s - F_c) exp(-(v / v_St)^2))

    (docs/realistic-rig.md, eq. S1-S2). With F_s = F_c and hold = 0 it is Table 2.2 exactly
    (the Stribeck term is 0, and ``stribeck_velocity`` is then irrelevant).

    Parameters
    ----------
    rate : coordinate velocity v [m/s or rad/s].
    active : every other generalized force on the coordinate, F_a [N or N m].
    viscous, coulomb, static : b [N s/m or N m s/rad], F_c and breakaway F_s [N or N m].
    width : stick band [m/s or rad/s].
    stribeck_velocity : v_St [m/s or rad/s].
    hold : extra force while stuck [N or N m] (the realistic plant brings a stuck coordinate
        to rest with it; Table 2.2 has none, so a coordinate can stick at up to +/- width).
    """
    level = coulomb + (static - coulomb) * ca.exp(-((rate / stribeck_velocity) ** 2))
    slipping = viscous * rate + ca.sign(rate) * level
    stuck = ca.logic_and(ca.fabs(rate) <= width, ca.fabs(active) <= static)
    return ca.if_else(stuck, active + hold, slipping)


@lru_cache(maxsize=32)
def discontinuous_dynamics(model: Model, law: str) -> ca.Function:
    """xdot = f(x, u, p, band) with the ``"stick-slip"`` (Table 2.2) or ``"sign"`` friction law
    on every friction-bearing coordinate (the band is ignored by ``"sign"``)."""
    x = ca.SX.sym("x", model.n_states)
    u = ca.SX.sym("u", model.n_inputs)
    p = ca.SX.sym("p", len(model.parameters))
    band = ca.SX.sym("band", 2)
    sites = friction_sites(model)
    n_q = model.n_states // 2
    mask = np.ones(len(model.parameters))
    for site in sites:
        mask[[site.viscous, site.coulomb]] = 0.0
    free = model.dynamics(x, u, p * ca.DM(mask), ca.DM([1.0, 1.0]))  # no friction at all
    mass = model.mass(p)
    active = ca.mtimes(mass, free[n_q:])  # generalized forces without friction [N or N m]
    friction = [ca.SX(0)] * n_q
    for site in sites:
        j = site.coordinate
        rate, viscous, coulomb = x[n_q + j], p[site.viscous], p[site.coulomb]
        if law == "sign":
            friction[j] = viscous * rate + coulomb * ca.sign(rate)
        else:
            width = band[0] if site.linear else band[1]
            friction[j] = stick_slip_force(rate, active[j], viscous, coulomb, coulomb, width)
    qddot = free[n_q:] - ca.solve(mass, ca.vertcat(*friction))
    return ca.Function(
        f"{law.replace('-', '_')}_dynamics",
        [x, u, p, band],
        [ca.vertcat(x[n_q:], qddot)],
        ["x", "u", "p", "s"],
        ["xdot"],
    )


def stick_slip_dynamics(model: Model) -> ca.Function:
    """xdot = f(x, u, p, band) with Table 2.2's friction on every friction-bearing coordinate."""
    return discontinuous_dynamics(model, "stick-slip")


def dynamics_function(model: Model, friction: FrictionOptions) -> ca.Function:
    """(x, u, p, s) -> xdot for the chosen friction law."""
    if friction.model == "smooth":
        return model.dynamics
    return discontinuous_dynamics(model, friction.model)


def stick_slip_substeps(
    model: Model, p: np.ndarray, dt: float, band: tuple[float, float], minimum: int = 4
) -> int:
    """RK4 substeps per sample for stick-slip friction.

    Two conditions: (1) the friction-free dynamics are stable (``stable_substeps`` with Coulomb
    zero: belt modes and viscous damping only), and (2) Coulomb deceleration alone changes a
    coasting coordinate's velocity by at most one band half-width per substep, F_c / m h <= band,
    so that a stopping coordinate lands in the band instead of jumping across it and chattering.
    """
    p = np.asarray(p, dtype=float)
    frictionless = p.copy()
    mass = np.diag(np.asarray(model.mass(p)))
    needed = minimum
    for site in friction_sites(model):
        frictionless[site.coulomb] = 0.0
        rate = p[site.coulomb] / mass[site.coordinate]
        width = band[0] if site.linear else band[1]
        needed = max(needed, math.ceil(dt * rate / width))
    return max(needed, stable_substeps(model, frictionless, dt, minimum=minimum))


#: Fewest RK4 substeps per sample under the sign law: the EMPS benchmark integrates its closed
#: loop with steps of at most a tenth of the sample time (Simulation_EMPS.m: ode45, 'MaxStep',
#: tec/10). The step sets the chattering about v = 0, and with it the acceleration error the
#: benchmark reports (measured on EMPS: 8.605 % at 4 substeps, 8.594 % at 10; published 8.604 %).
SIGN_MIN_SUBSTEPS = 10


def sign_substeps(model: Model, p: np.ndarray, dt: float) -> int:
    """RK4 substeps per sample for the sign law: ``SIGN_MIN_SUBSTEPS``, or more where the
    friction-free dynamics (Coulomb zero: belt modes, viscous damping) need them."""
    frictionless = np.array(p, dtype=float)
    for site in friction_sites(model):
        frictionless[site.coulomb] = 0.0
    return stable_substeps(model, frictionless, dt, minimum=SIGN_MIN_SUBSTEPS)
