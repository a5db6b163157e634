"""Trajectories of section 5.2 (eq. 5.8-5.12), workspace checks and the leg metrics."""

from pathlib import Path

import numpy as np
import pytest

from hframe_id.control.closed_loop import rest_state
from hframe_id.control.metrics import leg_metrics, perpendicular_error
from hframe_id.control.trajectory import (
    INCH_M,
    Leg,
    Workspace,
    end_effector_from_motor_angles,
    motor_angles,
    point_to_point,
    square,
)
from hframe_id.errors import ModelError, OptionError
from hframe_id.models import build_model
from hframe_id.parameters import load_parameter_file

MODELS = Path(__file__).resolve().parents[2] / "models"
R = 0.0194


def test_leg_time_and_profile_follow_eq_5_8_to_5_11():
    leg = Leg((0.0, 0.0), (INCH_M, 0.0), 6 * INCH_M, 0.2, 0.0)
    # eq. 5.11: T = d / (v_max (1 - f_a)) = 1 / (6 * 0.8) s; eq. 5.8: T_a = 0.2 T.
    assert leg.duration_s == pytest.approx(1 / 4.8)
    assert leg.accel_time_s == pytest.approx(0.2 / 4.8)
    t = np.linspace(0, leg.duration_s, 20001)
    s = leg.progress(t)
    v = np.gradient(s, t)
    assert s[0] == 0.0
    assert s[-1] == pytest.approx(INCH_M, abs=1e-15)
    assert v.max() == pytest.approx(6 * INCH_M, rel=1e-4)  # v_max on the cruise part
    a = np.gradient(v, t)
    inner = (t > 1e-3) & (t < leg.accel_time_s - 1e-3)
    np.testing.assert_allclose(a[inner], 6 * INCH_M / leg.accel_time_s, rtol=1e-3)
    assert np.all(np.diff(s) >= 0)  # the corrected deceleration branch never reverses


def test_square_is_the_thesis_test_path():
    path = square()
    assert [tuple(leg.direction) for leg in path.legs] == [(1, 0), (0, 1), (-1, 0), (0, -1)]
    assert path.end_time_s == pytest.approx(4 / 4.8)  # the 0.83 s square
    corners = path.position(np.array([leg.t_end_s for leg in path.legs]))
    np.testing.assert_allclose(corners, [[INCH_M, 0], [INCH_M, INCH_M], [0, INCH_M], [0, 0]],
                               atol=1e-15)  # fmt: skip
    # Section 5.8's variations.
    assert square(2 * INCH_M).legs[0].duration_s == pytest.approx(2 / 4.8)
    assert square(v_max_m_per_s=3 * INCH_M).legs[0].duration_s == pytest.approx(2 / 4.8)


def test_motor_angles_invert_eq_5_12_and_match_section_1_3():
    xy = np.random.default_rng(3).uniform(-0.05, 0.05, (10, 2))
    np.testing.assert_allclose(end_effector_from_motor_angles(motor_angles(xy, R), R), xy)
    # Section 1.3: x motion = the motors turning opposite ways, y motion = the same way; a
    # positive rotation of motor 1 alone moves the end-effector in -x and -y.
    phi_x, phi_y = motor_angles([[0.01, 0.0], [0.0, 0.01]], R)
    assert phi_x[0] == pytest.approx(-phi_x[1])
    assert phi_y[0] == pytest.approx(phi_y[1])
    assert np.all(end_effector_from_motor_angles([[1.0, 0.0]], R) < 0)


@pytest.mark.parametrize("file", ["hframe-8-table4.2.yaml", "hframe-20-table3.1.yaml"])
def test_rest_state_leaves_every_belt_unstretched(file):
    params = load_parameter_file(MODELS / file)
    model = build_model(params.variant)
    p = model.parameter_vector(params.values)
    x0 = rest_state(model, p, (0.013, -0.021))
    _, potential = model.energy(x0, p)
    assert float(potential) < 1e-18  # J; any stretch of 1 nm would store ~1e-14 J
    assert x0[model.index("state", "x")] == 0.013


def test_closed_loop_needs_an_hframe():
    params = load_parameter_file(MODELS / "one-axis-table2.3.yaml")
    model = build_model(params.variant)
    with pytest.raises(ModelError, match="H-frame"):
        rest_state(model, model.parameter_vector(params.values), (0.0, 0.0))


def test_workspace_rejects_paths_outside():
    Workspace().check(square())
    with pytest.raises(OptionError, match="leaves the workspace: leg 1 end"):
        Workspace().check(square(side_m=0.2))
    with pytest.raises(OptionError, match="leg 2 end"):
        Workspace(-0.1, 0.1, -0.01, 0.01).check(square())
    with pytest.raises(OptionError, match="min < max"):
        Workspace(0.1, -0.1)


@pytest.mark.parametrize(
    "kwargs",
    [{"side_m": -0.01}, {"v_max_m_per_s": 0}, {"f_a": 0.6}, {"f_a": 0}, {"settle_s": -1}],
)
def test_bad_square_rejected(kwargs):
    with pytest.raises(OptionError):
        square(**kwargs)


def test_point_to_point_moves():
    path = point_to_point([(0, 0), (0.01, 0.01), (0.01, 0.0)], dwell_s=0.1, settle_s=0.05)
    first, second = path.legs
    assert first.distance_m == pytest.approx(np.sqrt(2) * 0.01)
    assert second.t_start_s == pytest.approx(first.t_end_s + 0.1)
    assert path.end_time_s == pytest.approx(second.t_end_s + 0.05)
    dwell = path.position(np.array([first.t_end_s + 0.05]))
    np.testing.assert_allclose(dwell, [[0.01, 0.01]], atol=1e-15)
    with pytest.raises(OptionError):
        point_to_point([(0, 0)])
    with pytest.raises(OptionError, match="distinct"):
        point_to_point([(0, 0), (0, 0)])


def _synthetic(path, overshoot, undershoot, offset):
    """A path that follows the square, then overshoots leg 1 by ``overshoot`` (a smooth bump
    peaking on a sample 10 ms after the corner), stops ``undershoot`` short at the leg-2
    corner, and keeps ``offset`` in x during leg 2's constant-velocity part."""
    t = np.arange(0, path.end_time_s + 0.1, 1e-3)
    xy = path.position(t)
    leg1, leg2 = path.legs[:2]
    peak = round(leg1.t_end_s + 0.01, 3)
    xy[:, 0] += overshoot * np.exp(-(((t - peak) / 0.006) ** 2))
    cruise = (t >= leg2.cruise_s[0]) & (t < leg2.cruise_s[1])
    xy[cruise, 0] += offset
    late = t >= leg2.t_end_s - leg2.accel_time_s
    xy[late & (t < path.legs[2].t_start_s + 0.05), 1] = np.minimum(
        xy[late & (t < path.legs[2].t_start_s + 0.05), 1], INCH_M - undershoot
    )
    return t, xy


def test_metrics_recover_a_known_overshoot_undershoot_and_offset():
    path = square(settle_s=0.1)
    t, xy = _synthetic(path, overshoot=4e-4, undershoot=1e-4, offset=5e-5)
    metrics = leg_metrics(t, xy, path)
    assert metrics[0].overshoot_m == pytest.approx(4e-4, rel=1e-3)
    assert metrics[1].overshoot_m == pytest.approx(-1e-4, rel=1e-9)  # stopped short
    assert metrics[1].offset_max_m == pytest.approx(5e-5, rel=1e-9)
    assert metrics[0].offset_max_m == pytest.approx(0.0, abs=1e-15)
    # Leg 3 follows the path exactly: overshoot 0 when it stops at its end.
    assert metrics[2].overshoot_m == pytest.approx(0.0, abs=1e-12)


def test_overshoot_is_none_when_the_run_ends_first():
    path = square()
    t = path.sample_times(1e-3)
    lagging = path.position(t - 0.01)  # 10 ms behind: still moving when the reference ends
    assert leg_metrics(t, lagging, path)[3].overshoot_m is None


def test_perpendicular_error_sign_follows_fig_5_11():
    path = square()
    t = np.array([0.1, 0.3, 0.5, 0.7])  # inside legs 1..4
    shifted = path.position(t) + np.array([1e-5, 2e-5])
    # Above an x leg and right of a y leg count positive (Fig. 5.11).
    np.testing.assert_allclose(perpendicular_error(t, shifted, path), [2e-5, 1e-5, 2e-5, 1e-5])
