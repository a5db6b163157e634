"""Reduced H-frame 8th-order model: 4 DOF, three effective belt springs (Ch. 4, eq. 4.9-4.18).

Coordinates x, y, phi1, phi2 (Fig. 4.1). Springs: k_l (motor pulley 1 to the cart), k_r (cart
to motor pulley 2), k_b (between the motor pulleys, along the bridge). The printed eq.
4.20-4.23 and the a_ij of 4.25 contain typos; the equations here are derived from the energies
4.9-4.16 and the virtual work 4.17-4.18.
"""

from __future__ import annotations

from functools import partial

import casadi as ca

from hframe_id.models.common import (
    CURRENT_LIMIT,
    HFRAME_INPUTS,
    HFRAME_OUTPUTS,
    MEASURED,
    MOTOR_CONSTANTS,
    RADIUS,
    amplifier_gain,
    length_scaled_stiffness,
    limited_motor_torque,
    motor_torque,
    spring_energy,
    thesis_file,
)
from hframe_id.models.declaration import ModelDeclaration
from hframe_id.models.lagrange import Friction, LagrangianSystem
from hframe_id.models.options import ModelOptions
from hframe_id.models.spec import ParameterSpec, Signal

NAME = "hframe-8"
DESCRIPTION = "H-frame reduced 8th-order model, 4 DOF, springs k_l, k_r, k_b (Ch. 4)"

SPRINGS = ("l", "r", "b")

PARAMETERS = (
    RADIUS,
    ParameterSpec("k_l", "N/m", "effective belt stiffness, motor 1 to cart (eq. 4.6)"),
    ParameterSpec("k_r", "N/m", "effective belt stiffness, cart to motor 2 (eq. 4.7)"),
    ParameterSpec("k_b", "N/m", "effective belt stiffness between the motors (eq. 4.8)"),
    ParameterSpec("J_M1", "kg m^2", "lumped inertia at motor pulley 1 (eq. 4.2)"),
    ParameterSpec("J_M2", "kg m^2", "lumped inertia at motor pulley 2 (eq. 4.2)"),
    ParameterSpec("M_cart", "kg", "cart mass with lumped bridge-pulley inertia (eq. 4.3)"),
    ParameterSpec("M_bridge", "kg", "mass of the bridge with cart (x motion)"),
    ParameterSpec(
        "B_M1", "N m s/rad", "viscous friction at motor pulley 1 (eq. 4.4)", "nonnegative"
    ),
    ParameterSpec(
        "B_M2", "N m s/rad", "viscous friction at motor pulley 2 (eq. 4.4)", "nonnegative"
    ),
    ParameterSpec("b_cart", "N s/m", "viscous friction of the cart (eq. 4.5)", "nonnegative"),
    ParameterSpec("b_bridge", "N s/m", "viscous friction of the bridge", "nonnegative"),
    ParameterSpec("tau_cM1", "N m", "Coulomb friction torque at motor pulley 1", "nonnegative"),
    ParameterSpec("tau_cM2", "N m", "Coulomb friction torque at motor pulley 2", "nonnegative"),
    ParameterSpec("F_c_cart", "N", "Coulomb friction force of the cart", "nonnegative"),
    ParameterSpec("F_c_bridge", "N", "Coulomb friction force of the bridge", "nonnegative"),
    *MOTOR_CONSTANTS,
    amplifier_gain(1),
    amplifier_gain(2),
    *(
        ParameterSpec(
            f"l_{s}0", "m", f"length of belt k_{s} at the origin (eq. 4.39-4.41)", required=False
        )
        for s in SPRINGS
    ),
)

COORDINATES = (
    Signal("x", "m", "end-effector (bridge) position"),
    Signal("y", "m", "end-effector (cart) position"),
    Signal("phi1", "rad", "angle of motor pulley 1"),
    Signal("phi2", "rad", "angle of motor pulley 2"),
)
INPUTS = HFRAME_INPUTS
OUTPUTS = HFRAME_OUTPUTS

#: Length change of the effective springs with the end-effector position (eq. 4.39-4.41).
_LENGTH_CHANGE = {"l": (1, 1), "r": (1, -1), "b": (-2, 0)}


def stretches(q: ca.SX, r: ca.SX) -> dict[str, ca.SX]:
    """Stretch [m] of the springs k_l, k_r, k_b (eq. 4.13-4.15)."""
    x, y, phi1, phi2 = q[0], q[1], q[2], q[3]
    return {
        "l": phi1 * r + x + y,
        "r": -phi2 * r + x - y,
        "b": -phi1 * r + phi2 * r - 2 * x,
    }


def lagrangian(
    p: dict[str, ca.SX], u: ca.SX, options: ModelOptions, torque=motor_torque
) -> LagrangianSystem:
    """Energies (eq. 4.9-4.16) and virtual work (eq. 4.17-4.18) of the 8th-order model, each
    motor's torque [N m] by ``torque(p, voltage, gain name, pulley rate)``."""
    q = ca.SX.sym("q", 4)
    qdot = ca.SX.sym("qdot", 4)
    kinetic = 0.5 * (
        p["M_bridge"] * qdot[0] ** 2
        + p["M_cart"] * qdot[1] ** 2
        + p["J_M1"] * qdot[2] ** 2
        + p["J_M2"] * qdot[3] ** 2
    )
    potential = ca.SX(0)
    for spring, stretch in stretches(q, p["r"]).items():
        stiffness = p[f"k_{spring}"]
        if options.position_dependent_stiffness:
            sx, sy = _LENGTH_CHANGE[spring]
            stiffness = length_scaled_stiffness(stiffness, p[f"l_{spring}0"], sx * q[0] + sy * q[1])
        potential += spring_energy(stiffness, stretch)
    actuation = ca.vertcat(
        0,
        0,
        torque(p, u[0], "g_1", qdot[2]),
        torque(p, u[1], "g_2", qdot[3]),
    )
    frictions = (
        Friction("x", "b_bridge", "F_c_bridge"),
        Friction("y", "b_cart", "F_c_cart"),
        Friction("phi1", "B_M1", "tau_cM1"),
        Friction("phi2", "B_M2", "tau_cM2"),
    )
    return LagrangianSystem(COORDINATES, q, qdot, kinetic, potential, actuation, frictions)


DECLARATION = ModelDeclaration(
    name=NAME,
    description=DESCRIPTION,
    parameters=PARAMETERS,
    coordinates=COORDINATES,
    inputs=INPUTS,
    outputs=OUTPUTS,
    lagrangian=lagrangian,
    reference_file=thesis_file("hframe-8-table4.2.yaml"),
    reference_label="Table 4.1 + 4.2",
    fixed=MEASURED + ("l_l0", "l_r0", "l_b0"),  # belt lengths are measured geometry (section 4.6)
    source=__name__,
    nests_in="hframe-8-current-limit",
)

#: hframe-8 with each amplifier limiting its motor's current to +/- I_max (``common.
#: limited_current``): the realistic rig's amplifiers do (8 A, docs/realistic-rig.md (A1)), and
#: a fit of hframe-8 tries it where the records may reach a limit (``nests_in`` below,
#: ``hframe_id.fitting.structure_choice``). hframe-8 is its limit I_max -> infinity. I_max is
#: held like the motor constants (a data-sheet value) unless a fit frees it.
CURRENT_LIMITED = ModelDeclaration(
    name="hframe-8-current-limit",
    description="H-frame reduced 8th-order model with current-limited amplifiers (Ch. 4 + a "
    "servo amplifier's peak current)",
    parameters=(*PARAMETERS, CURRENT_LIMIT),
    coordinates=COORDINATES,
    inputs=INPUTS,
    outputs=OUTPUTS,
    lagrangian=partial(lagrangian, torque=limited_motor_torque),
    reference_file=thesis_file("hframe-8-current-limit.yaml"),
    reference_label="Table 4.1 + 4.2, 8 A amplifiers",
    fixed=DECLARATION.fixed + ("I_max",),
    source=__name__,
)
