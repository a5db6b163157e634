"""The EMPS axis with direction-dependent friction: M q'' = gtau vir - F_fr(q') - F_0.

The rigid axis of ``emps_axis.py`` (Janot, Gautier, Brunot, "Data Set and Reference Models of
EMPS", 2019) with the asymmetric friction of the benchmark description (section 4, eq. 12):
the ballscrew's viscous and Coulomb friction differ with the direction of motion,

    F_fr = w+ (F_v_pos q' + F_c_pos s) + w- (F_v_neg q' + F_c_neg s),
    s = tanh(q' / v_s),  w+ = (1 + s) / 2,  w- = (1 - s) / 2,

the sign of the velocity smoothed exactly as ``emps_axis.py`` smooths its Coulomb force (tanh,
v_s = 1 mm/s, the model option's default linear smoothing velocity), so that the fit stays
differentiable; with s -> sign(q') it is the description's eq. 12. With equal positive and
negative values it is ``emps_axis.py``'s law, F_v q' + F_c s, term for term.

The description publishes an asymmetric IDIM-LS estimate (Script_IDIM_LS_Asym_Fric.m, without
an offset term): ``emps-directional-idim.yaml``.

The library's friction declaration takes one (viscous, Coulomb) pair per coordinate, so this
law is written as a generalized force: simulators' ``--friction sign`` and ``stick-slip``
replace only declared friction and leave this one smoothed (docs/real-data.md), and it keeps
v_s = 1 mm/s whatever the model options say.

    hframe-id fit --model-file models/emps_axis_directional.py datasets/real/emps-estimation.mcap
"""

import casadi as ca

from hframe_id.models import ParameterSpec, Signal, declare
from hframe_id.models.options import DEFAULT_SMOOTHING_LINEAR_M_PER_S

#: Smoothing velocity of the velocity's sign [m/s]: emps_axis.py's Coulomb smoothing.
V_S_M_PER_S = DEFAULT_SMOOTHING_LINEAR_M_PER_S


def friction(qdot, p):
    """Direction-dependent viscous plus Coulomb friction force [N] (module docstring)."""
    s = ca.tanh(qdot / V_S_M_PER_S)
    positive, negative = (1 + s) / 2, (1 - s) / 2
    return positive * (p["F_v_pos"] * qdot + p["F_c_pos"] * s) + negative * (
        p["F_v_neg"] * qdot + p["F_c_neg"] * s
    )


def equations(q, qdot, u, p):
    """Energies and forces: a moving mass, the drive force, the offset and the friction."""
    return {
        "kinetic": 0.5 * p["M"] * qdot["qm"] ** 2,
        "potential": 0,
        "forces": {"qm": p["gtau"] * u["vir"] - p["F_0"] - friction(qdot["qm"], p)},
    }


MODEL = declare(
    name="emps-axis-directional",
    description="EMPS ballscrew axis, rigid body with direction-dependent viscous and Coulomb "
    "friction and an offset (Janot et al. 2019, eq. 12)",
    coordinates=[Signal("qm", "m", "motor position, at the load")],
    inputs=[Signal("vir", "V", "controller output (motor drive reference)")],
    outputs=["qm"],
    parameters=[
        ParameterSpec("M", "kg", "moving mass, motor and screw inertia at the load"),
        ParameterSpec("F_v_pos", "N s/m", "viscous friction, positive velocity"),
        ParameterSpec("F_v_neg", "N s/m", "viscous friction, negative velocity"),
        ParameterSpec("F_c_pos", "N", "Coulomb friction, positive velocity", "nonnegative"),
        ParameterSpec("F_c_neg", "N", "Coulomb friction, negative velocity", "nonnegative"),
        ParameterSpec("F_0", "N", "constant offset force (e.g. gravity, amplifier offset)", "real"),
        ParameterSpec("gtau", "N/V", "drive gain: motor force per volt of controller output"),
    ],
    equations=equations,
    reference="emps-directional-idim.yaml",
    reference_label="asymmetric IDIM-LS, Janot et al. 2019",
    fixed=("gtau",),
    # As emps_axis.py: the axis is an integrator under closed-loop position control, so
    # independent 50 ms horizons keep the open-loop drift out of the fit (docs/real-data.md).
    fit_defaults={"shooting_interval": 50, "continuity": "none"},
)
