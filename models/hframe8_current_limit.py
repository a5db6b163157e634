"""The H-frame 8th-order model (Ch. 4) with its amplifiers' current limit: a user model.

``hframe_id.models.hframe8`` (energies eq. 4.9-4.16, virtual work eq. 4.17-4.18) with each
motor's torque through the smooth current limit of ``one_axis_current_limit.py``: K_t i_lim,
i = (g_m u_m - K_e phidot_m) / R limited to +/- I_max. The realistic sim rig's amplifiers
limit their current to 8 A (docs/realistic-rig.md, (A1)), reached from about 5.7 V at 0.71 ohm:
the section-4.4 steps at 6 V do. I_max is the amplifier's data-sheet value, held in fits like
the motor constants. Where the data sheet is unknown and the steps reach the limit, I_max can
be fitted with the rest (``--free default,I_max``): on two drawn plants of issue 25 (limits
6.9 and 7.7 A) it came to 7.6 and 7.0 A, determined, and the fit predicted held-out records
14-24 x better than the plant's own linear reduction. On plants without a limit it puts one
where it helps the training records: 8.75 A, "poorly determined", 2.4 x worse than hframe-8
held out; on another 8.16 A, determined to 1.4 %, 2.07 x worse than the reduction. So
whether I_max is determined does not tell whether the rig has a limit; held-out records do
(docs/studies/2026-11-28-fitting-the-current-limit.md).

The thesis's belt lengths (section 4.6, position-dependent stiffness) are not parameters here:
a user model's equations do not see the model options, so the model has constant stiffness
(hframe-8's default).

    hframe-id fit --model-file models/hframe8_current_limit.py \\
        --initial models/hframe-8-current-limit.yaml RECORDING.mcap ...
    hframe-id fit --model-file models/hframe8_current_limit.py --free default,I_max \\
        --initial models/hframe-8-current-limit.yaml RECORDING.mcap ...
"""

from hframe_id.models import ParameterSpec, declare, hframe8, sibling_module
from hframe_id.models.common import MEASURED, spring_energy


#: The one-axis model's smooth limit (a clip with rounded corners): one limiter for both models.
limited_current = sibling_module(__file__, "one_axis_current_limit.py").limited_current

#: (coordinate, amplifier gain, input) of each motor.
MOTORS = (("phi1", "g_1", "u1"), ("phi2", "g_2", "u2"))


def equations(q, qdot, u, p):
    """Energies and forces of hframe-8 (as ``hframe_id.models.hframe8``), each motor torque
    through the current limit."""
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
        "friction": {
            "x": ("b_bridge", "F_c_bridge"),
            "y": ("b_cart", "F_c_cart"),
            "phi1": ("B_M1", "tau_cM1"),
            "phi2": ("B_M2", "tau_cM2"),
        },
    }


MODEL = declare(
    name="hframe-8-current-limit",
    description="H-frame reduced 8th-order model with current-limited amplifiers (Ch. 4 + a "
    "servo amplifier's peak current)",
    coordinates=list(hframe8.COORDINATES),
    inputs=list(hframe8.INPUTS),
    outputs=list(hframe8.OUTPUTS),
    parameters=[
        *(spec for spec in hframe8.PARAMETERS if spec.required),  # not the belt lengths
        ParameterSpec("I_max", "A", "amplifier current limit (data sheet)"),
    ],
    equations=equations,
    reference="hframe-8-current-limit.yaml",
    reference_label="Table 4.1 + 4.2, 8 A amplifiers",
    fixed=(*MEASURED, "I_max"),
    held=hframe8.DECLARATION.held,
)
