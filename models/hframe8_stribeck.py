"""The H-frame 8th-order model with current-limited amplifiers and Stribeck friction: a user
model.

``hframe8_current_limit.py`` (Ch. 4 with the amplifiers' current limit) with a Stribeck curve
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

from hframe_id.models import ParameterSpec, declare, sibling_module


current_limited = sibling_module(__file__, "hframe8_current_limit.py")

#: coordinate: (viscous, Coulomb, static, Stribeck velocity) parameter names.
FRICTION = {
    "x": ("b_bridge", "F_c_bridge", "F_s_bridge", "v_St_linear"),
    "y": ("b_cart", "F_c_cart", "F_s_cart", "v_St_linear"),
    "phi1": ("B_M1", "tau_cM1", "tau_sM1", "v_St_motor"),
    "phi2": ("B_M2", "tau_cM2", "tau_sM2", "v_St_motor"),
}


def equations(q, qdot, u, p):
    """``hframe8_current_limit.equations`` with a Stribeck curve on every friction."""
    return {**current_limited.equations(q, qdot, u, p), "friction": FRICTION}


MODEL = declare(
    name="hframe-8-stribeck",
    description="H-frame reduced 8th-order model with current-limited amplifiers and "
    "Stribeck friction (Ch. 4 + a servo amplifier's peak current + a breakaway peak)",
    coordinates=current_limited.MODEL.coordinates,
    inputs=current_limited.MODEL.inputs,
    outputs=current_limited.MODEL.outputs,
    parameters=[
        *current_limited.MODEL.parameters,
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
    fixed=current_limited.MODEL.fixed,
    held=current_limited.MODEL.held,
)
