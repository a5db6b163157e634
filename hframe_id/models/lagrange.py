"""Equations of motion from Lagrange's equations (eq. 3.1), derived symbolically in CasADi.

A variant declares its generalized coordinates, kinetic energy T(q, qdot), potential energy
V(q) stored in the belt springs, the actuation part of the generalized non-conservative forces
(motor torques, eq. 2.4 / 3.26) and which coordinates carry friction. This module derives

    d/dt(dL/dqdot) - dL/dq = Q_nc,    L = T - V,

as  M(q) qddot = Q_nc + dT/dq - dV/dq - (d^2 T / dqdot dq) qdot,  solved for qddot.
Friction on every friction-bearing coordinate is viscous plus smoothed Coulomb,
Q_fr = -(b qdot + F_c tanh(qdot / v_s)), with v_s chosen by the coordinate's unit; a
coordinate may add a Stribeck curve, the Coulomb level rising to the static (breakaway)
level F_s at rest: F_c + (F_s - F_c) exp(-(qdot / v_St)^2) in place of F_c.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

from hframe_id.models.spec import Signal


@dataclass(frozen=True)
class Friction:
    """Friction acting on one generalized coordinate.

    ``viscous`` and ``coulomb`` name the parameters (viscous coefficient, Coulomb level);
    ``static`` and ``stribeck_velocity``, if given, a Stribeck curve's breakaway level and
    velocity (same units as ``coulomb`` and the coordinate's rate).
    """

    coordinate: str
    viscous: str
    coulomb: str
    static: str | None = None
    stribeck_velocity: str | None = None

    @property
    def parameters(self) -> tuple[str, ...]:
        """The names of every parameter this friction uses."""
        stribeck = (self.static, self.stribeck_velocity) if self.static else ()
        return (self.viscous, self.coulomb, *stribeck)

    def level(self, parameters: dict[str, ca.SX], rate: ca.SX) -> ca.SX:
        """The sliding friction level [N or N m] at ``rate``: F_c, or with a Stribeck curve
        F_c + (F_s - F_c) exp(-(rate / v_St)^2)."""
        coulomb = parameters[self.coulomb]
        if self.static is None:
            return coulomb
        decay = ca.exp(-((rate / parameters[self.stribeck_velocity]) ** 2))
        return coulomb + (parameters[self.static] - coulomb) * decay


@dataclass(frozen=True)
class LagrangianSystem:
    """Symbolic ingredients of one model variant (all SX expressions).

    Attributes
    ----------
    coordinates : generalized coordinates q with units ("m" or "rad").
    q, qdot : SX column vectors of coordinates and their rates.
    kinetic_energy : T(q, qdot, p) [J].
    potential_energy : V(q, p) [J].
    actuation : generalized forces other than friction, Q_act(q, qdot, u, p) [N or N m].
    frictions : the friction-bearing coordinates.
    """

    coordinates: tuple[Signal, ...]
    q: ca.SX
    qdot: ca.SX
    kinetic_energy: ca.SX
    potential_energy: ca.SX
    actuation: ca.SX
    frictions: tuple[Friction, ...]


def friction_forces(
    system: LagrangianSystem, parameters: dict[str, ca.SX], smoothing: ca.SX
) -> ca.SX:
    """Generalized friction forces Q_fr (viscous + tanh-smoothed Coulomb, with a Stribeck
    curve where declared: ``Friction.level``) per coordinate.

    ``smoothing`` is a 2-vector (v_s linear [m/s], v_s angular [rad/s]).
    """
    names = [c.name for c in system.coordinates]
    forces = [ca.SX(0)] * len(names)
    for friction in system.frictions:
        j = names.index(friction.coordinate)
        unit = system.coordinates[j].unit
        v_s = smoothing[0] if unit == "m" else smoothing[1]
        rate = system.qdot[j]
        forces[j] = -(
            parameters[friction.viscous] * rate
            + friction.level(parameters, rate) * ca.tanh(rate / v_s)
        )
    return ca.vertcat(*forces)


def mass_matrix(system: LagrangianSystem) -> ca.SX:
    """M(q) = d^2 T / dqdot^2."""
    hessian, _ = ca.hessian(system.kinetic_energy, system.qdot)
    return hessian


def accelerations(
    system: LagrangianSystem, parameters: dict[str, ca.SX], smoothing: ca.SX
) -> ca.SX:
    """qddot from Lagrange's equations with friction, by a symbolic mass-matrix solve."""
    q, qdot = system.q, system.qdot
    T, V = system.kinetic_energy, system.potential_energy
    dT_dqdot = ca.gradient(T, qdot)
    coriolis = ca.jacobian(dT_dqdot, q) @ qdot
    rhs = (
        system.actuation
        + friction_forces(system, parameters, smoothing)
        + ca.gradient(T, q)
        - ca.gradient(V, q)
        - coriolis
    )
    return ca.solve(mass_matrix(system), rhs)
