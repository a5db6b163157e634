"""The compiled inner loop (``fitting.kernel``): one RK4 substep, with the exact sensitivities
of the discrete map to the state and the free parameters."""

import casadi as ca
import numpy as np
import pytest

from hframe_id.fitting.kernel import compiled_substep, state_substep_function, substep_function
from hframe_id.models import build_model

FREE = (0, 3, 5)  # r, k_b, J_M2 (indices in model.parameters): sensitivities carried


@pytest.fixture(scope="module")
def point(table):
    """hframe-8 in motion (speeds far above the Coulomb smoothing), under 4 V, -3 V."""
    model = build_model("hframe-8")
    p = model.parameter_vector(table.values)
    x = np.array([0.3, -0.2, 0.01, -0.02, 40.0, -25.0, 0.2, -0.1])
    return model, x, np.array([4.0, -3.0]), p, np.array([1e-3, 1e-2]), 1e-4


def test_the_state_is_the_substep_without_sensitivities_bit_for_bit(point):
    model, x, u, p, s, h = point
    sens = np.hstack([np.eye(8), np.zeros((8, len(FREE)))])
    x_next, _ = substep_function(model, FREE)(x, sens, u, p, s, h)
    plain = state_substep_function(model)(x, u, p, s, h)
    np.testing.assert_array_equal(np.asarray(x_next), np.asarray(plain))
    assert np.max(np.abs(np.asarray(plain).ravel() - x)) > 1e-6  # it moved


def test_sensitivities_from_the_identity_are_the_maps_derivatives(point):
    """S_next = dPhi/dx S + [0, dPhi/dp_free] from S = [I, 0]: the Jacobian of the substep in
    (x, p_free), against central differences (step 1e-6 relative: truncation and round-off
    both below 1e-7 of the largest entry; tolerance 1e-6 of it)."""
    model, x, u, p, s, h = point
    sens = np.hstack([np.eye(8), np.zeros((8, len(FREE)))])
    _, sens_next = compiled_substep(model, FREE)(x, sens, u, p, s, h)
    sens_next = np.asarray(sens_next)
    step_of = state_substep_function(model)
    columns = []
    for k in range(8 + len(FREE)):
        xk, pk = [x.copy(), x.copy()], [p.copy(), p.copy()]
        target, index = (xk, k) if k < 8 else (pk, FREE[k - 8])
        delta = 1e-6 * (abs(target[0][index]) or 1.0)
        target[0][index] += delta
        target[1][index] -= delta
        ends = [np.asarray(step_of(xk[i], u, pk[i], s, h)).ravel() for i in (0, 1)]
        columns.append((ends[0] - ends[1]) / (2 * delta))
    numeric = np.column_stack(columns)
    scale = np.max(np.abs(numeric))
    np.testing.assert_allclose(sens_next, numeric, rtol=0, atol=1e-6 * scale)
    assert isinstance(compiled_substep(model, FREE), ca.Function)
