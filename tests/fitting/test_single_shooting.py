"""A fit's all-window stage as an unconstrained least-squares problem (``fitting
.single_shooting``): its Jacobian is that of its residuals, and it exists only for one
trajectory per record."""

import numpy as np
import pytest

from hframe_id.errors import OptionError
from hframe_id.fitting import FitOptions
from hframe_id.fitting.problem import build_problem
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.fitting.single_shooting import SingleShooting
from hframe_id.fitting.solver import SolverState

FREE = ("k_l", "b_bridge")


def _single_shooting(table, recording, **options):
    options = FitOptions(free=FREE, **options).for_model("hframe-8")
    problem = build_problem([recording], table, options)
    ms = MultipleShooting(problem, transcription=options.transcription_options)
    nodes, _ = ms.initial_nodes(ms.problem.p_initial)
    state = SolverState(nodes, np.zeros(len(FREE)), np.ones(len(FREE), dtype=bool))
    return SingleShooting(ms, state)


def test_the_jacobian_is_the_residuals_derivative(table, x_step):
    """Central differences in every unknown (the initial rigid-mode amplitudes, then log k_l and
    log b_bridge): truncation and round-off below 1e-6 of the largest entry here; the
    tolerance, 1e-4 of it, is the condensed Jacobian's own test's."""
    shooting = _single_shooting(table, x_step(table, seed=6))
    z = shooting.start() + np.r_[np.zeros(shooting.start().size - 2), 0.05, -0.1]
    jac = shooting.jacobian(z)
    assert jac.shape == (shooting.residual(z).size, z.size)
    for k in range(z.size):
        h = 1e-6 if k >= z.size - 2 else 1e-8
        dz = np.eye(z.size)[k] * h
        numeric = (shooting.residual(z + dz) - shooting.residual(z - dz)) / (2 * h)
        scale = np.max(np.abs(numeric))
        assert scale > 0, k
        np.testing.assert_allclose(jac[:, k], numeric, rtol=0, atol=1e-4 * scale)


def test_prediction_error_windows_have_no_single_shooting(table, x_step):
    with pytest.raises(OptionError, match="single shooting needs one trajectory per record"):
        _single_shooting(table, x_step(table, seed=6), continuity="none", shooting_interval=50)
