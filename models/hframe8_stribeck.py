"""The H-frame 8th-order model with current-limited amplifiers and Stribeck friction: a user
model.

The built-in hframe-8-current-limit (Ch. 4 with the amplifiers' current limit,
``hframe_id.models.hframe8``) with a Stribeck curve
on each friction-bearing coordinate: the Coulomb level rises from F_c to a static (breakaway)
level F_s at rest, F_c + (F_s - F_c) exp(-(v / v_St)^2) (``hframe_id.models.lagrange``). The
realistic sim rig's friction has such a peak (docs/realistic-rig.md, (S1)); a model without
it cannot both hold still where the rig does not break away (the 2 V steps) and slide where
it does. One Stribeck velocity for the two motors and one for the two linear axes keep the
added parameters to six.

The start values (``hframe-8-stribeck.yaml``) are guesses, not the plant's: F_s = 1.5 F_c,
v_St = 0.5 rad/s and 10 mm/s.

    hframe-id fit --model-file models/hframe8_stribeck.py RECORDING.mcap ...
"""

from hframe_id.models import ParameterSpec, declaration, declare, hframe8
from hframe_id.models.common import MEASURED, limited_current, spring_energy

#: The built-in model this one extends by a Stribeck curve.
LIMITED = declaration("hframe-8-current-limit")

#: (coordinate, amplifier gain, input) of each motor.
MOTORS = (("phi1", "g_1", "u1"), ("phi2", "g_2", "u2"))

#: coordinate: (viscous, Coulomb, static, Stribeck velocity) parameter names.
FRICTION = {
    "x": ("b_bridge", "F_c_bridge", "F_s_bridge", "v_St_linear"),
    "y": ("b_cart", "F_c_cart", "F_s_cart", "v_St_linear"),
    "phi1": ("B_M1", "tau_cM1", "tau_sM1", "v_St_motor"),
    "phi2": ("B_M2", "tau_cM2", "tau_sM2", "v_St_motor"),
}


def equations(q, qdot, u, p):
    """Energies (eq. 4.9-4.16) and forces of hframe-8-current-limit, a Stribeck curve on every
    friction. The belt lengths (section 4.6) are not parameters: a user model's equations do
    not see the model options, so the stiffness is constant (hframe-8's default)."""
    stretch = hframe8.stretches([q[c.name] for c in hframe8.COORDINATES], p["r"])
    forces = {}
    for rate, gain, volts in MOTORS:
        current = (p[gain] * u[volts] - p["K_e"] * qdot[rate]) / p["R"]
        forces[rate] = p["K_t"] * limited_current(current, p["I_max"])
    return {
        "kinetic": 0.5
        * (
            p["M_bridge"] * qdot["x"] ** 2
            + p["M_cart"] * qdot["y"] ** 2
            + p["J_M1"] * qdot["phi1"] ** 2
            + p["J_M2"] * qdot["phi2"] ** 2
        ),
        "potential": sum(spring_energy(p[f"k_{s}"], stretch[s]) for s in hframe8.SPRINGS),
        "forces": forces,
        "friction": FRICTION,
    }


MODEL = declare(
    name="hframe-8-stribeck",
    description="H-frame reduced 8th-order model with current-limited amplifiers and "
    "Stribeck friction (Ch. 4 + a servo amplifier's peak current + a breakaway peak)",
    coordinates=list(hframe8.COORDINATES),
    inputs=list(hframe8.INPUTS),
    outputs=list(hframe8.OUTPUTS),
    parameters=[
        *(spec for spec in LIMITED.parameters if spec.required),  # not the belt lengths
        ParameterSpec("tau_sM1", "N m", "motor 1 static (breakaway) friction torque"),
        ParameterSpec("tau_sM2", "N m", "motor 2 static (breakaway) friction torque"),
        ParameterSpec("F_s_cart", "N", "cart static (breakaway) friction force"),
        ParameterSpec("F_s_bridge", "N", "bridge static (breakaway) friction force"),
        ParameterSpec("v_St_motor", "rad/s", "Stribeck velocity of the motors"),
        ParameterSpec("v_St_linear", "m/s", "Stribeck velocity of cart and bridge"),
    ],
    equations=equations,
    reference="hframe-8-stribeck.yaml",
    reference_label="Table 4.1 + 4.2, 8 A amplifiers, guessed Stribeck curves",
    fixed=(*MEASURED, "I_max"),
    held=LIMITED.held,
)
