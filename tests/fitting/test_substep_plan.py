"""RK4 substeps per sample of the shooting windows (``fitting.substep_plan``), on hand-made
Jacobians whose spectral radii and Coulomb rates are known exactly. (The Coulomb rates of
the H-frame model itself: tests/fitting/test_stiffness_wall.py; the stiff count against the
simulators' ``stable_substeps``: tests/simulation/test_simulation_integrator.py.)"""

import math

import numpy as np
import pytest

from hframe_id.fitting.link_options import TranscriptionOptions
from hframe_id.fitting.substep_plan import (
    coordinate_smoothing,
    coulomb_rates,
    plan_substeps,
    stopped_message,
)
from hframe_id.models import build_model
from hframe_id.simulation.integrators import RK4_STABILITY_LIMIT

DT = 1e-3  # s, the rigs' sample period
#: One coordinate in m, one in rad (smoothing velocities in m/s and rad/s).
SMOOTHING = (0.001, 0.01)


def _jacobians(belt_rate: float, coulomb: tuple[float, float]):
    """(df/dx at rest, df/dx in motion) of two coordinates: a belt mode of spectral radius
    ``belt_rate`` [1/s] in both, and at rest each velocity's own rate raised by its Coulomb
    rate ``coulomb`` [1/s]."""
    moving = np.zeros((4, 4))
    moving[0, 2] = moving[1, 3] = 1.0
    moving[2, 0] = moving[3, 1] = -(belt_rate**2)  # undamped: eigenvalues +/- i belt_rate
    rest = moving.copy()
    rest[2, 2] -= coulomb[0]
    rest[3, 3] -= coulomb[1]
    return rest, moving


def test_each_coordinate_is_smoothed_by_the_velocity_of_its_unit():
    model = build_model("hframe-8")
    vs = coordinate_smoothing(model, SMOOTHING)
    units = [c.unit for c in model.coordinates]
    assert {"m", "rad"} <= set(units)
    assert vs.tolist() == [SMOOTHING[0] if u == "m" else SMOOTHING[1] for u in units]


def test_the_coulomb_rate_is_a_velocitys_own_rate_at_rest_less_that_in_motion():
    rest, moving = _jacobians(330.0, (4.5e4, 2.0e3))
    assert coulomb_rates(rest, moving) == pytest.approx([4.5e4, 2.0e3], rel=1e-15)


def test_moving_windows_need_the_belt_modes_count_and_stiff_ones_the_count_at_rest():
    """Both counts from |lambda| h <= 2.785 / safety: the fast one at the belt modes' radius
    (at least 4 substeps), the stiff one at the largest rate at rest."""
    options = TranscriptionOptions()
    rest, moving = _jacobians(330.0, (4.5e4, 2.0e3))
    plan = plan_substeps(rest, moving, np.array(SMOOTHING), DT, options)
    safety = options.substep_safety
    assert plan["fast"] == max(4, math.ceil(330.0 * DT * safety / RK4_STABILITY_LIMIT))
    radius_rest = float(np.max(np.abs(np.linalg.eigvals(rest))))
    assert plan["stiff"] == math.ceil(radius_rest * DT * safety / RK4_STABILITY_LIMIT)
    assert plan["stiff"] > plan["fast"] and not plan["refused"]


def test_a_window_is_stiff_below_the_speed_where_its_coulomb_rate_needs_more_substeps():
    """At the threshold speed v, lambda sech^2(v / v_s) h is half the stable |lambda| h with
    the fast count (the plan's margin); a velocity whose rate the fast count integrates
    anyway (here the second) has no threshold."""
    options = TranscriptionOptions()
    rest, moving = _jacobians(330.0, (4.5e4, 100.0))
    plan = plan_substeps(rest, moving, np.array(SMOOTHING), DT, options)
    v = plan["threshold"][0]
    h = DT / plan["fast"]
    slope = 4.5e4 / math.cosh(v / SMOOTHING[0]) ** 2
    assert slope * h == pytest.approx(0.5 * RK4_STABILITY_LIMIT / options.substep_safety)
    assert plan["threshold"][1] == 0.0


def test_a_point_whose_stability_at_rest_needs_more_than_max_substeps_is_refused():
    """The cap limits the safety margin, never stability: beyond it the point is refused."""
    rest, moving = _jacobians(330.0, (4.5e4, 2.0e3))
    stable = math.ceil(4.5e4 * DT / RK4_STABILITY_LIMIT)  # 17
    capped = plan_substeps(
        rest, moving, np.array(SMOOTHING), DT, TranscriptionOptions(max_substeps=20)
    )
    assert capped["stiff"] == 20 and not capped["refused"]  # 1.5 x margin cut to the cap
    refused = plan_substeps(
        rest, moving, np.array(SMOOTHING), DT, TranscriptionOptions(max_substeps=stable - 1)
    )
    assert refused["stiff"] == stable and refused["refused"]


def test_a_stopped_stage_says_whether_the_point_was_too_stiff_or_overflowed():
    assert "needs 600 substeps per sample, more than max_substeps 500" in stopped_message(600, 500)
    assert stopped_message(300, 500).startswith("stopped: the model's sensitivities overflow")
