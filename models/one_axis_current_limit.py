"""The one-axis belt drive (Ch. 2) with its amplifier's current limit: a user model.

The thesis's motor torque (eq. 2.4) is K_t (g_1 u - K_e phidot_1) / R: the amplifier follows
its command at any current. A servo amplifier limits its current instead; the realistic sim
rig does (docs/realistic-rig.md, (A1)-(A2): 8 A, reached by the 10 V one-axis pulse). Here
the current is limited smoothly,

    i_lim = i - s(i - I_max) + s(-i - I_max),   s(z) = w ln(1 + e^(z / w)),  w = 0.02 A
    (``hframe_id.models.common.limited_current``, shared with the built-in hframe-8-current-limit),

a clip with its corners rounded over a few w: i to 1e-20 A up to I_max - 1 A, I_max - w ln 2
at i = I_max (0.17 % below the plant's clip at 8 A), I_max to 1e-10 A from I_max + 0.5 A on.
I_max is the amplifier's data-sheet value, held in fits like the motor constants.

    hframe-id fit --model-file models/one_axis_current_limit.py \\
        --initial models/one-axis-current-limit.yaml datasets/realistic/5V_oneaxis.mcap \\
        datasets/realistic/10V_oneaxis.mcap
"""

from hframe_id.models import declare, one_axis
from hframe_id.models.common import CURRENT_LIMIT, limited_current


def equations(q, qdot, u, p):
    """Energies and forces of the one-axis drive (as ``hframe_id.models.one_axis``), the motor
    torque through the current limit."""
    r = p["r"]
    current = (p["g_1"] * u["u1"] - p["K_e"] * qdot["phi1"]) / p["R"]
    return {
        "kinetic": 0.5
        * (p["J_1"] * qdot["phi1"] ** 2 + p["M"] * qdot["x"] ** 2 + p["J_2"] * qdot["phi3"] ** 2),
        "potential": 0.5 * p["k1"] * (q["phi1"] * r - q["x"]) ** 2
        + 0.5 * p["k2"] * (q["x"] - q["phi3"] * r) ** 2
        + 0.5 * p["k3"] * (r * (q["phi3"] - q["phi1"])) ** 2,
        "forces": {"phi1": p["K_t"] * limited_current(current, p["I_max"])},
        "friction": {"phi1": ("B_1", "tau_c1"), "x": ("b", "F_c"), "phi3": ("B_2", "tau_c2")},
    }


MODEL = declare(
    name="one-axis-current-limit",
    description="one-axis belt drive with a current-limited amplifier (Ch. 2 + a servo "
    "amplifier's peak current)",
    coordinates=list(one_axis.COORDINATES),
    inputs=list(one_axis.INPUTS),
    outputs=list(one_axis.OUTPUTS),
    parameters=[
        *one_axis.PARAMETERS,
        CURRENT_LIMIT,
    ],
    equations=equations,
    reference="one-axis-current-limit.yaml",
    reference_label="Table 2.1 + 2.3, 8 A amplifier",
    fixed=("r", "K_t", "K_e", "R", "g_1", "I_max"),
    held=("J_2", "B_2", "tau_c2"),
)
