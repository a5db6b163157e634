"""A DC servo's rotor driven by voltage, measured by a tachometer and a current shunt.

One rotating body of inertia J (motor and load) on one coordinate ``theta`` [rad]; the
amplifier (gain g) puts g V across the armature (resistance R, inductance neglected: the
electrical time constant L / R is far below the sample period), whose current
I = (g V - K theta') / R [A] makes the torque K I against viscous (B) and Coulomb (tau_c)
friction, K the torque and back-EMF constant [N m/A = V s/rad]:

    J theta'' = K (g V - K theta') / R - B theta' - tau_c sign(theta')

Neither output is a coordinate: the tachometer measures the speed theta' [rad/s], the shunt
the current (g V - K theta') / R [A] (docs/custom-models.md, "Outputs that are not
coordinates"). Their ``noise_std`` are the sensors' data-sheet noise, used unless a
recording's rig metadata declare their own. K and R are the motor's data sheet (held); J, B,
tau_c and the amplifier gain g are fitted. No published parameter set comes with it: a fit
starts from the user's data-sheet values (``--initial``).

    hframe-id fit --model-file models/dc_servo.py --initial servo-catalogue.yaml run1.mcap
"""

from hframe_id.models import Output, ParameterSpec, Signal, declare


def equations(q, qdot, u, p):
    """Energies and forces: a rotor, the armature current's torque."""
    return {
        "kinetic": 0.5 * p["J"] * qdot["theta"] ** 2,
        "potential": 0,
        "forces": {"theta": p["K"] * current(q, qdot, u, p)},
        "friction": {"theta": ("B", "tau_c")},
    }


def speed(q, qdot, u, p):
    """The tachometer's reading [rad/s]."""
    return qdot["theta"]


def current(q, qdot, u, p):
    """The armature current [A]: the amplifier's voltage less the back EMF, over R."""
    return (p["g"] * u["V"] - p["K"] * qdot["theta"]) / p["R"]


MODEL = declare(
    name="dc-servo",
    description="DC servo rotor driven by voltage, rigid body with viscous and Coulomb "
    "friction, tachometer and armature-current outputs",
    coordinates=[Signal("theta", "rad", "rotor angle")],
    inputs=[Signal("V", "V", "amplifier input voltage")],
    outputs=[
        Output("omega", "rad/s", "tachometer speed", speed, noise_std=0.5),
        Output("current", "A", "armature current, from the shunt", current, noise_std=0.01),
    ],
    parameters=[
        ParameterSpec("J", "kg m^2", "rotor and load inertia"),
        ParameterSpec("B", "N m s/rad", "viscous friction", "nonnegative"),
        ParameterSpec("tau_c", "N m", "Coulomb friction", "nonnegative"),
        ParameterSpec("K", "N m/A", "torque and back-EMF constant (data sheet)"),
        ParameterSpec("R", "Ohm", "armature resistance (data sheet)"),
        ParameterSpec("g", "V/V", "amplifier gain"),
    ],
    equations=equations,
    fixed=("K", "R"),
)
