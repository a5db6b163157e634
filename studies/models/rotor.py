"""A servo's rotor under commanded torque: J theta'' = tau + tau_0 - B theta' - tau_c sign(theta').

One rotating body of inertia J (motor and load) on one coordinate ``theta`` [rad], driven by
the torque ``tau`` [N m] that the drive is commanded (a current-controlled amplifier: torque
= torque constant x current, the constant taken as exact), against viscous (B) and Coulomb
(tau_c) friction and a constant offset torque tau_0 (amplifier offset, an unbalanced load).
Its catalogue values, the default start of a fit, are ``rotor-catalogue.yaml``.

The sign of the Coulomb torque is smoothed the way the thesis's models are:
tau_c tanh(theta' / v_s), with the model option's angular smoothing velocity v_s (0.01 rad/s).

    hframe-id fit --model-file studies/models/rotor.py run1.mcap run2.mcap run3.mcap
"""

from hframe_id.models import ParameterSpec, Signal, declare


def equations(q, qdot, u, p):
    """Energies and forces: a rotor, the commanded torque and a constant offset torque."""
    return {
        "kinetic": 0.5 * p["J"] * qdot["theta"] ** 2,
        "potential": 0,
        "forces": {"theta": u["tau"] + p["tau_0"]},
        "friction": {"theta": ("B", "tau_c")},
    }


MODEL = declare(
    name="rotor",
    description="servo rotor under commanded torque, rigid body with viscous and Coulomb "
    "friction and an offset torque",
    coordinates=[Signal("theta", "rad", "rotor angle, from the motor encoder")],
    inputs=[Signal("tau", "N m", "commanded motor torque")],
    outputs=["theta"],
    parameters=[
        ParameterSpec("J", "kg m^2", "rotor and load inertia"),
        ParameterSpec("B", "N m s/rad", "viscous friction", "nonnegative"),
        ParameterSpec("tau_c", "N m", "Coulomb friction", "nonnegative"),
        ParameterSpec("tau_0", "N m", "constant offset torque (amplifier offset)", "real"),
    ],
    equations=equations,
    reference="rotor-catalogue.yaml",
    reference_label="catalogue (data sheet) values",
)
