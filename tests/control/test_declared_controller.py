"""Declared controllers run on any model: the closed-loop simulator against exact references."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.linalg

from hframe_id.control import PIDGains, load_controller_file, pid_controller
from hframe_id.control.closed_loop import rest_state, simulate_closed_loop
from hframe_id.control.loop import simulate_loop
from hframe_id.control.pid import ControllerOptions
from hframe_id.control.trajectory import motor_angles, square
from hframe_id.models import build_model, load_model_file
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.recording import Recording
from hframe_id.resources import models_dir
from hframe_id.simulation.friction import FrictionOptions

EMPS_CONTROLLER = models_dir() / "emps_controller.py"


def _recording(time_s, signals: dict, inputs=("vir",), outputs=("qm",), units=None):
    """A recording holding ``signals`` (name -> values) and zero inputs and outputs."""
    n = time_s.size
    units = units or {"vir": "V", "qm": "m", "qg": "m", "pulses_N": "V"}
    return Recording(
        variant="test",
        sample_period_s=float(time_s[1] - time_s[0]),
        time_s=time_s,
        inputs=np.zeros((n, len(inputs))),
        input_names=tuple(inputs),
        outputs=np.zeros((n, len(outputs))),
        output_names=tuple(outputs),
        valid=np.ones((n, len(outputs)), dtype=bool),
        units={k: v for k, v in units.items() if k in (*inputs, *outputs, *signals)},
        signals=np.column_stack(list(signals.values())),
        signal_names=tuple(signals),
    )


def _emps_model():
    return build_model(load_model_file(models_dir() / "emps_axis.py").name)


def _exact_emps_loop(values, gains, reference, pulses, dt, limit=10.0):
    """The EMPS loop with the plant advanced by its exact zero-order-hold discretization
    (matrix exponential of M q'' = gtau u - F_v q' - F_0, no Coulomb friction): the oracle.
    Returns positions, velocities and applied inputs at the sample instants."""
    m, f_v, f_0, g = values["M"], values["F_v"], values["F_0"], values["gtau"]
    a = np.array([[0.0, 1.0], [0.0, -f_v / m]])
    b = np.array([[0.0], [1.0 / m]])  # input: the force gtau u - F_0
    block = scipy.linalg.expm(np.block([[a, b], [np.zeros((1, 3))]]) * dt)
    a_d, b_d = block[:2, :2], block[:2, 2]
    x, q_prev, qf_prev, waiting = np.zeros(2), 0.0, 0.0, 0.0
    states, applied = [], []
    for r, w in zip(reference, pulses, strict=True):
        qf = 0.5 * x[0] + 0.5 * q_prev
        command = gains["kv"] * (gains["kp"] * (r - x[0]) - (qf - qf_prev) / dt)
        q_prev, qf_prev = x[0], qf
        u = np.clip(waiting, -limit, limit) + w
        waiting = command
        states.append(x.copy())
        applied.append(u)
        x = a_d @ x + b_d * (g * u - f_0)
    return np.array(states), np.array(applied)


def test_emps_loop_matches_the_exact_discretization():
    """A linear plant (no Coulomb friction) under the EMPS loop, its reference saturating the
    10 V output and a pulse added after the saturation: every sample against the exact
    zero-order-hold discretization. RK4 with 10 substeps of 0.1 ms on a mode of F_v / M =
    2.1 1/s errs by ~(lambda h)^5 per step; 1e-9 relative leaves room for rounding only."""
    model = _emps_model()
    values = dict(load_parameter_file(models_dir() / "emps-idim-ls.yaml").values, F_c=0.0)
    p = model.parameter_vector(values)
    controller = load_controller_file(EMPS_CONTROLLER)
    dt = 1e-3
    time_s = np.arange(3000) * dt
    reference = 0.05 * (time_s > 0.1) - 0.02 * np.sin(4 * time_s)  # a 5 cm step: saturates
    pulses = np.where((time_s > 1.5) & (time_s < 1.6), 2.0, 0.0)
    recording = _recording(time_s, {"qg": reference, "pulses_N": pulses})
    run = simulate_loop(model, p, controller, recording, np.zeros(2), FrictionOptions("sign"))
    gains = {g.name: g.value for g in controller.gains}
    states, applied = _exact_emps_loop(values, gains, reference, pulses, dt)
    assert run.sample_period_s == dt and run.disturbances == ("pulses_N",)
    assert np.count_nonzero(np.abs(applied) == 10.0) > 5  # the step saturates the output
    np.testing.assert_allclose(run.inputs[:, 0], applied, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(run.states, states, rtol=1e-9, atol=1e-12)
    # The accelerations logged at t_k are the plant's under the input applied from t_k.
    force = values["gtau"] * applied - values["F_0"] - values["F_v"] * states[:, 1]
    np.testing.assert_allclose(run.accelerations[:, 0], force / values["M"], atol=1e-9)


def test_the_declared_pid_on_recorded_references_runs_the_chapter_5_loop():
    """The built-in PID (reset_windup_pid, checked against the Appendix A port in
    test_control_pid.py) on hframe-8 along the test square, its references read from a
    recording's signals: what simulate_closed_loop runs from the path, to round-off."""
    model = build_model("hframe-8")
    params = load_parameter_file(models_dir() / "hframe-8-table4.2.yaml")
    p = model.parameter_vector(params.values)
    options = ControllerOptions.from_gains(150, 100, 4)
    trajectory = square()
    thesis = simulate_closed_loop(model, p, trajectory, options)
    time_s = thesis.time_s[:-1]
    phi = motor_angles(trajectory.position(time_s), float(params.values["r"]))
    recording = _recording(
        time_s,
        {"phi1_ref": phi[:, 0], "phi2_ref": phi[:, 1]},
        inputs=("u1", "u2"),
        outputs=("phi1", "phi2"),
        units={"u1": "V", "u2": "V", "phi1": "rad", "phi2": "rad", "phi1_ref": "rad",
               "phi2_ref": "rad"},
    )  # fmt: skip
    controller = pid_controller(
        {"u1": ("phi1", "phi1_ref"), "u2": ("phi2", "phi2_ref")}, PIDGains(150, 100, 4)
    )
    x0 = rest_state(model, p, trajectory.start_m)
    run = simulate_loop(model, p, controller, recording, x0, n_substeps=thesis.n_substeps)
    np.testing.assert_allclose(run.states, thesis.states[:-1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(run.inputs, thesis.voltages_v, rtol=0, atol=1e-12)


def test_a_controller_reads_its_references_at_its_own_clock():
    """A controller period shorter than the recording's: the reference is read at k T by
    linear interpolation (Simulink's Repeating Sequence), and the run has floor(D / T) + 1
    samples."""
    model = _emps_model()
    p = model.parameter_vector(load_parameter_file(models_dir() / "emps-idim-ls.yaml").values)
    controller = load_controller_file(EMPS_CONTROLLER)
    time_s = np.arange(1001) * 1e-3
    recording = _recording(time_s, {"qg": 0.01 * time_s})
    fast = replace(controller, sample_period_s=0.9e-3)
    run = simulate_loop(model, p, fast, recording, np.zeros(2))
    assert run.time_s.size == 1112  # floor(1 / 0.9e-3) + 1
    np.testing.assert_allclose(run.references[:, 0], 0.01 * run.time_s, rtol=1e-12)
