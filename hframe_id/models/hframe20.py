"""H-frame 20th-order model: 10 DOF, nine belt sections (Chapter 3, eq. 3.3-3.26).

Coordinates x (bridge), y (cart on the bridge) and the pulley angles phi1..phi8 (Fig. 3.2):
1, 2 motor pulleys; 3, 4 stationary corner pulleys; 5..8 pulleys on the bridge. The bridge
pulleys' masses m_p5..m_p8 of eq. 3.9-3.12 are taken as part of M_bridge (Table 3.1 lists no
separate values). The printed eq. 3.27 has sign and index typos; the equations here are derived
from the energies 3.3-3.21 and the virtual work 3.25.
"""

from __future__ import annotations

import casadi as ca

from hframe_id.models.common import (
    HFRAME_INPUTS,
    HFRAME_OUTPUTS,
    MEASURED,
    MOTOR_CONSTANTS,
    RADIUS,
    amplifier_gain,
    length_scaled_stiffness,
    motor_torque,
    spring_energy,
    thesis_file,
)
from hframe_id.models.declaration import ModelDeclaration
from hframe_id.models.lagrange import Friction, LagrangianSystem
from hframe_id.models.options import ModelOptions
from hframe_id.models.spec import ParameterSpec, Signal

NAME = "hframe-20"
DESCRIPTION = "H-frame 20th-order model, 10 DOF, nine belt sections (Ch. 3, eq. 3.3-3.26)"

PULLEYS = range(1, 9)
BELT_SECTIONS = range(1, 10)

PARAMETERS = (
    RADIUS,
    *(ParameterSpec(f"k_{i}", "N/m", f"stiffness of belt section {i}") for i in BELT_SECTIONS),
    *(ParameterSpec(f"J_{i}", "kg m^2", f"inertia of pulley {i}") for i in PULLEYS),
    ParameterSpec("M_cart", "kg", "mass of the cart (y motion)"),
    ParameterSpec("M_bridge", "kg", "mass of the bridge with cart and pulleys (x motion)"),
    *(
        ParameterSpec(f"B_{i}", "N m s/rad", f"viscous friction of pulley {i}", "nonnegative")
        for i in PULLEYS
    ),
    ParameterSpec("b_cart", "N s/m", "viscous friction of the cart", "nonnegative"),
    ParameterSpec("b_bridge", "N s/m", "viscous friction of the bridge", "nonnegative"),
    *(
        ParameterSpec(f"tau_c{i}", "N m", f"Coulomb friction torque of pulley {i}", "nonnegative")
        for i in PULLEYS
    ),
    ParameterSpec("F_c_cart", "N", "Coulomb friction force of the cart", "nonnegative"),
    ParameterSpec("F_c_bridge", "N", "Coulomb friction force of the bridge", "nonnegative"),
    *MOTOR_CONSTANTS,
    amplifier_gain(1),
    amplifier_gain(2),
    *(
        ParameterSpec(
            f"l_{i}", "m", f"length of belt section {i} at the origin (sec. 4.6)", required=False
        )
        for i in (3, 4, 5, 6, 7, 8)
    ),
)

COORDINATES = (
    Signal("x", "m", "end-effector (bridge) position"),
    Signal("y", "m", "end-effector (cart) position"),
    *(Signal(f"phi{i}", "rad", f"angle of pulley {i}") for i in PULLEYS),
)
INPUTS = HFRAME_INPUTS
OUTPUTS = HFRAME_OUTPUTS

#: Length change of belt sections 3..8 with the end-effector position (eq. 4.35-4.38);
#: sections 1, 2 and 9 keep their length (eq. 4.34), so they have no length parameter.
_LENGTH_CHANGE = {3: (-1, 0), 4: (-1, 0), 5: (1, 0), 6: (1, 0), 7: (0, 1), 8: (0, -1)}


def stretches(q: ca.SX, r: ca.SX) -> list[ca.SX]:
    """Stretch [m] of belt sections 1..9 (eq. 3.13-3.21)."""
    x, y = q[0], q[1]
    phi = {i: q[1 + i] for i in PULLEYS}
    return [
        r * (phi[1] - phi[3]),
        r * (-phi[2] + phi[4]),
        -phi[1] * r - phi[5] * r - x,
        phi[2] * r + phi[6] * r - x,
        phi[3] * r + phi[7] * r + x,
        -phi[4] * r - phi[8] * r + x,
        -phi[7] * r + y,
        phi[8] * r - y,
        r * (phi[5] - phi[6]),
    ]


def lagrangian(p: dict[str, ca.SX], u: ca.SX, options: ModelOptions) -> LagrangianSystem:
    """Energies (eq. 3.3-3.21) and virtual work (eq. 3.25-3.26) of the 20th-order model."""
    q = ca.SX.sym("q", 10)
    qdot = ca.SX.sym("qdot", 10)
    kinetic = 0.5 * (p["M_bridge"] * qdot[0] ** 2 + p["M_cart"] * qdot[1] ** 2)
    for i in PULLEYS:
        kinetic += 0.5 * p[f"J_{i}"] * qdot[1 + i] ** 2
    potential = ca.SX(0)
    for i, stretch in zip(BELT_SECTIONS, stretches(q, p["r"]), strict=True):
        stiffness = p[f"k_{i}"]
        if options.position_dependent_stiffness and i in _LENGTH_CHANGE:
            sx, sy = _LENGTH_CHANGE[i]
            stiffness = length_scaled_stiffness(stiffness, p[f"l_{i}"], sx * q[0] + sy * q[1])
        potential += spring_energy(stiffness, stretch)
    actuation = ca.vertcat(
        0,
        0,
        motor_torque(p, u[0], "g_1", qdot[2]),
        motor_torque(p, u[1], "g_2", qdot[3]),
        *([0] * 6),
    )
    frictions = (
        Friction("x", "b_bridge", "F_c_bridge"),
        Friction("y", "b_cart", "F_c_cart"),
        *(Friction(f"phi{i}", f"B_{i}", f"tau_c{i}") for i in PULLEYS),
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
    reference_file=thesis_file("hframe-20-table3.1.yaml"),
    reference_label="Table 3.1",
    # Belt lengths are measured geometry (section 4.6).
    fixed=(*MEASURED, *(f"l_{i}" for i in (3, 4, 5, 6, 7, 8))),
    source=__name__,
)
