"""Reset-windup PID of Appendix A: the literal port, its CasADi form, and the closed loop."""

from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from hframe_id.control.closed_loop import simulate_closed_loop
from hframe_id.control.pid import ControllerOptions, PIDGains, ResetWindupPID, reset_windup_pid
from hframe_id.control.trajectory import motor_angles, square
from hframe_id.errors import OptionError
from hframe_id.models import build_model
from hframe_id.parameters import load_parameter_file
from hframe_id.simulation.integrators import rk4_step, stable_substeps

MODELS = Path(__file__).resolve().parents[2] / "models"
T = 1e-3


def test_unsaturated_output_is_p_plus_i_plus_d():
    pid = ResetWindupPID(PIDGains(150, 100, 4))
    u0 = pid.step(actual=0.0, desired=0.01)
    # P 1.5 V, D 4 * 0.01 / 1 ms = 40 V -> P + D clipped to 10 V; trial I = 1e-3 >= 0 and
    # 10 + 1e-3 > 10, so the integral is reset to 10 - 10 = 0 (Appendix A).
    assert u0 == 10.0
    assert pid.integral == 0.0
    u1 = pid.step(actual=0.0, desired=0.01)  # no error change: D = 0
    assert u1 == pytest.approx(1.5 + 100 * 0.01 * T)
    assert pid.integral == pytest.approx(100 * 0.01 * T)


def test_trial_integral_clipped_to_the_headroom():
    pid = ResetWindupPID(PIDGains(100, 1000, 0))
    pid.integral = 2.0
    pid.previous_error = 0.09
    u = pid.step(0.0, 0.09)  # P 9 V, trial I 2 + 1000 * 0.09 * 1e-3 = 2.09 -> m = 11.09
    assert u == 10.0
    assert pid.integral == pytest.approx(1.0)  # Max - mpd


def test_negative_limit_and_opposite_sign_integral():
    pid = ResetWindupPID(PIDGains(100, 1000, 0))
    pid.integral = -2.0
    pid.previous_error = -0.09
    assert pid.step(0.0, -0.09) == -10.0
    assert pid.integral == pytest.approx(-1.0)  # Min - mpd
    # P + D saturated high but the trial integral is negative: it is accepted and pulls the
    # output off the limit (the code, not the prose of section 5.1).
    pid = ResetWindupPID(PIDGains(1000, 10, 0))
    pid.integral = -3.0
    pid.previous_error = 0.02
    assert pid.step(0.0, 0.02) == pytest.approx(10.0 - 3.0 + 10 * 0.02 * T)
    assert pid.integral == pytest.approx(-3.0 + 10 * 0.02 * T)


def test_pd_is_ki_zero():
    pid = ResetWindupPID(PIDGains(175, 0, 4))
    errors = np.random.default_rng(1).normal(0, 0.01, 50)
    for e in errors:
        pid.step(0.0, e)
        assert pid.integral == 0.0


def test_casadi_form_equals_the_port_on_random_errors():
    # Large gains and errors so that every branch of the windup logic is visited.
    rng = np.random.default_rng(7)
    e, e_prev, integral = ca.SX.sym("e"), ca.SX.sym("e_prev"), ca.SX.sym("i")
    k = ca.SX.sym("k", 3)
    out, new_integral = reset_windup_pid(e, e_prev, integral, k[0], k[1], k[2], T, -10.0, 10.0)
    step = ca.Function("pid", [e, e_prev, integral, k], [out, new_integral])
    branches = set()
    for _ in range(20):
        gains = PIDGains(*rng.uniform([0, 0, 0], [300, 3000, 8]))
        pid = ResetWindupPID(gains)
        previous, stored = 0.0, 0.0
        for error in np.cumsum(rng.normal(0, 0.004, 200)):  # persistent errors wind I up
            expected = pid.step(0.0, error)
            u, stored_next = step(error, previous, stored, [gains.kp, gains.ki, gains.kd])
            assert float(u) == pytest.approx(expected, abs=1e-12)
            assert float(stored_next) == pytest.approx(pid.integral, abs=1e-12)
            if abs(expected) == 10.0:
                branches.add("high" if expected > 0 else "low")
            else:
                branches.add("inside, I >= 0" if pid.integral >= 0 else "inside, I < 0")
            previous, stored = error, float(stored_next)
    assert len(branches) == 4


@pytest.mark.parametrize(
    "gains", [(-1, 0, 0), (1, float("nan"), 0), (1, 0, float("inf")), (True, 0, 0)]
)
def test_bad_gains_rejected(gains):
    with pytest.raises(OptionError):
        PIDGains(*gains)


def test_bad_controller_options_rejected():
    gains = PIDGains(150, 100, 4)
    with pytest.raises(OptionError, match="sample period"):
        ControllerOptions(gains, gains, sample_period_s=-1e-3)
    with pytest.raises(OptionError, match="gain scale"):
        ControllerOptions.from_gains(150, 100, 4, motor2_gain_scale=0)
    with pytest.raises(OptionError, match="delay"):
        ControllerOptions(gains, gains, delay_samples=-1)
    with pytest.raises(OptionError, match="limits"):
        ControllerOptions(gains, gains, u_min_v=1.0)


def _python_loop(model, p, trajectory, controller):
    """Fig. 5.8 sample by sample: sample phi(t_k), two Appendix A PIDs, hold u_k for T."""
    step = rk4_step(model, stable_substeps(model, p, T), T)
    s = ca.DM(model.options.smoothing)
    times = trajectory.sample_times(T)
    reference = motor_angles(trajectory.position(times), p[model.index("parameter", "r")])
    loops = [ResetWindupPID(controller.motor1), ResetWindupPID(controller.motor2)]
    angles = [model.index("state", "phi1"), model.index("state", "phi2")]
    x = np.zeros(model.n_states)
    queue = [np.zeros(2)] * controller.delay_samples
    states = [x]
    for k in range(times.size - 1):
        u = np.array([loops[i].step(x[angles[i]], reference[k, i]) for i in range(2)])
        queue.append(u)
        x = step(x, queue.pop(0), p, s).full().ravel()
        states.append(x)
    return np.array(states)


@pytest.fixture(scope="module")
def plant():
    params = load_parameter_file(MODELS / "hframe-8-table4.2.yaml")
    model = build_model(params.variant)
    return model, model.parameter_vector(params.values)


@pytest.mark.parametrize("delay", [0, 1])
def test_closed_loop_function_equals_sample_by_sample_loop(plant, delay):
    # Per-motor gains (motor 2 x 1.1, section 5.7), a high K_I that saturates the output:
    # the mapped CasADi graph must reproduce the plain loop to round-off.
    model, p = plant
    controller = ControllerOptions.from_gains(150, 1500, 4, motor2_gain_scale=1.1)
    controller = controller.with_delay(delay)
    trajectory = square(settle_s=0.05)
    result = simulate_closed_loop(model, p, trajectory, controller)
    expected = _python_loop(model, p, trajectory, controller)
    np.testing.assert_allclose(result.states, expected, rtol=1e-9, atol=1e-12)
    assert np.abs(result.voltages_v).max() == 10.0  # the limits were hit


def test_integral_terms_and_errors_are_reported(plant):
    model, p = plant
    result = simulate_closed_loop(model, p, square(), ControllerOptions.from_gains(150, 100, 4))
    # Fig. 5.18: the integral terms stay well inside the limits for K_I = 100 and, with the
    # motors lagging on leg 1 (motor 1 turns negative, motor 2 positive for +x), start with
    # opposite signs.
    assert np.abs(result.integral_v).max() < 1.0
    leg1 = result.time_s < 0.2
    assert np.sign(result.integral_v[leg1][-1]).tolist() == [-1.0, 1.0]
    np.testing.assert_allclose(
        result.motor_error_rad, result.phi_rad - result.reference_phi_rad, atol=0
    )
