"""The EMPS position loop, as the benchmark's Simulink model runs it (Simulink_EMPS_Rigide.slx).

The closed loop of the Electro-Mechanical Positioning System benchmark (A. Janot, M. Gautier,
M. Brunot, "Data Set and Reference Models of EMPS", Workshop on Nonlinear System
Identification Benchmarks, 2019), read block by block from the .slx (a zip of XML:
``simulink/blockdiagram.xml``); ``Simulink_EMPS_Rigide_Pulse.slx`` is the same loop with the
pulses added. Per sample k (t_k = k T):

    qf_k = 0.5 q_k + 0.5 q_{k-1}          block "filter", Numerator filterq1 = [0.5 0.5]
    dq_k = (qf_k - qf_{k-1}) / T          block "derivative", [1 -1] / [tec]
    w_k  = kv (kp (qg_k - q_k) - dq_k)     Sum1 (-q +qg), "gain kp", Sum2 (-dq +), "gain kv"
    vir  = sat(w_{k-1}, -10 V, 10 V)      "Unit Delay" (SampleTime tec), "sat_vir" +/-viradm
    plant input = vir + pulses_N(t_k)     Sum3 (pulse set only), into the plant subsystem

Where each number comes from:

- kp = 160.18 [1/s] and kv = 243.45 [V/(m/s)]: the gain blocks read the workspace variables
  ``kp`` and ``kv``, loaded from DATA_EMPS.mat (the recording's rig metadata ``kp``, ``kv``).
- filterq1 = [0.5 0.5]: Simulation_EMPS.m ("For filtering the position"); initial states 0.
- viradm = 10 [V]: Simulation_EMPS.m ("Maximum voltage (saturation)").
- The one-sample delay: block "Unit Delay", initial condition 0, at the sample time.
- T = tec = t(10) - t(9): Simulation_EMPS.m sets the sample time of the discrete blocks (and
  of the logged signals) from the .mat's time stamps; the reference ``qg`` and the pulses
  ``pulses_N`` are Repeating Sequence blocks over (t, qg) and (t, pulses_N), read at k tec by
  linear interpolation. For DATA_EMPS.mat, tec = 0.999983961121758 ms, 16 ns shorter than the
  recording's mean period (24.84 s / 24840 = 1 ms exactly): the simulated reference runs ahead
  of the recording's samples by up to 0.4 ms at the end of the record. ``hframe-id import``
  rounds the time stamps to the log's microsecond clock, so the period is looked up here by
  the source file's sha256 (``experiment.source.sha256`` of the recording); any other
  recording runs at its own period. This drift is most of the published position error: at
  the recording's 1 ms the IDIM-LS set's closed-loop position error is 0.0016 %, against the
  0.01375 % the benchmark reports (docs/real-data.md).
- pulses_N: added after the saturation, before the drive gain gtau (Sum3 in the pulse model):
  the plant input ``vir`` then holds controller output and pulse alike, as the benchmark's
  ``vir_s`` does; the description calls the pulses "in Newton", the Simulink model adds them
  to the voltage. Held over the sample here (the Repeating Sequence ramps between samples).

The plant is the model's (``models/emps_axis.py``: gtau, M, F_v, F_c, F_0 from the parameter
file). Use it with ``hframe-id validate ... --controller models/emps_controller.py``.
"""

from hframe_id.control import Gain, declare_controller
from hframe_id.models import Signal

#: The Simulink sample time tec = t(10) - t(9) of each benchmark file [s], by the sha256 of the
#: .mat (``hframe-id import`` records it as the recording's ``experiment.source.sha256``).
BENCHMARK_SAMPLE_TIMES_S = {
    # DATA_EMPS.mat (estimation set): t(10) - t(9) = 0.000999983961121758 s.
    "6cf6814ae14618795da0101aae2bb97ff0c6351b0501b5492751b02b07facf7e": 0.000999983961121758,
}


def sample_period(recording):
    """tec of the benchmark file the recording was imported from, else its own period [s]."""
    source = recording.experiment.get("source.sha256")
    return BENCHMARK_SAMPLE_TIMES_S.get(source, recording.sample_period_s)


def law(y, r, z, g, sample_period_s):
    """Position loop with an inner velocity loop on the 2-tap filtered position derivative."""
    q = y["qm"]
    qf = 0.5 * q + 0.5 * z["q_prev"]
    dq = (qf - z["qf_prev"]) / sample_period_s
    vir = g["kv"] * (g["kp"] * (r["qg"] - q) - dq)
    return {"commands": {"vir": vir}, "states": {"q_prev": q, "qf_prev": qf}}


CONTROLLER = declare_controller(
    name="emps-position-loop",
    description="EMPS position loop (Janot et al. 2019, Simulink_EMPS_Rigide.slx): P position "
    "loop, P velocity loop on a 2-tap filtered derivative, one-sample delay, 10 V saturation",
    commands=[Signal("vir", "V", "controller output (motor drive reference)")],
    measured=["qm"],
    references=[Signal("qg", "m", "position reference")],
    states=[
        Signal("q_prev", "m", "previous position sample (block 'filter')"),
        Signal("qf_prev", "m", "previous filtered position (block 'derivative')"),
    ],
    gains=[
        Gain("kp", 160.18, "1/s", "position loop gain (block 'gain kp'; DATA_EMPS.mat kp)"),
        Gain("kv", 243.45, "V/(m/s)", "velocity loop gain (block 'gain kv'; DATA_EMPS.mat kv)"),
    ],
    law=law,
    sample_period_s=sample_period,
    delay_samples=1,
    limits={"vir": (-10.0, 10.0)},
    disturbances={"vir": "pulses_N"},
)
