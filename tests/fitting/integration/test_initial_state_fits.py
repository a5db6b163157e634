"""Whole fits from records at rest and in motion: the initial state at rest where a record shows
rest, estimated where it starts in motion.

What the fit reports must be what ``hframe-id validate`` reproduces from the written file,
and validate simulates from rest at the first measured positions (issue 25, item 1).
"""

import numpy as np
import pytest

from hframe_id.fitting import FitOptions, fit_recordings
from hframe_id.fitting.known_points import simulation_criterion
from hframe_id.fitting.problem import build_problem, rest_projector
from hframe_id.models import build_model
from hframe_id.validation.replay import channels, rest_state

#: A small free set (stiffness, mass, viscous and Coulomb friction) for fast fits.
FREE = ("k_l", "k_r", "M_cart", "b_cart", "F_c_cart")


@pytest.fixture(scope="module")
def step(table, x_step):
    """A 4 V x-motion step from rest (50 samples of pre-roll)."""
    return x_step(table, seed=7)


def test_a_record_at_rest_starts_at_rest(table, step):
    """A record at rest starts with every velocity zero and the belts unstretched, its
    belt-free position estimated (within a sensor's resolution of the replay's rest state):
    its file, simulated from there, reproduces the fit's cost (a free initial velocity once
    hid a 20x worse replay)."""
    result = fit_recordings([step], table, FitOptions(free=FREE))
    assert result.success, result.message
    model = build_model("hframe-8")
    p = model.parameter_vector(result.parameters.values)
    rest = rest_state(model, p, channels(model, step))
    assert np.all(result.initial_states[0][4:] == 0.0)
    resolution = np.array([5e-6, 5e-6, 1.96e-5, 1.96e-5])  # x, y: laser std; phi: encoder step
    assert np.all(np.abs(result.initial_states[0][:4] - rest[:4]) < resolution)
    # Unstretched: on the rigid modes (the same at any stiffness; rounding of 1e-15 rad).
    x0 = result.initial_states[0]
    np.testing.assert_allclose(rest_projector(model, p) @ x0, x0, rtol=0, atol=1e-15)
    std = dict(result.diagnostics.channel_std)
    replayed = simulation_criterion(result.parameters, [step], std, None, result.initial_states)
    # The same RK4 (substeps from the same parameters): equal to the defects left (1e-2 std).
    assert replayed == pytest.approx(result.cost, rel=1e-4)
    assert "initial states at rest: " in result.summary()


def test_estimated_on_request_and_for_records_in_motion(table, step, in_motion):
    moving = in_motion(step, 150)
    result = fit_recordings([moving], table, FitOptions(free=FREE))
    assert result.success, result.message
    assert result.initial_states[0][4:].any()  # a velocity was estimated
    assert "initial states estimated: " in result.summary()
    estimated = build_problem([step], table, FitOptions(free=FREE, initial_state="estimate"))
    assert not estimated.experiments[0].at_rest
    forced = build_problem([moving], table, FitOptions(free=FREE, initial_state="rest"))
    assert forced.experiments[0].at_rest
