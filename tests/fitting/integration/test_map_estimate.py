"""Held parameters estimated with a prior (``FitOptions.consider_method="prior"``): which
parameters get one, and how it enters the cost, the Gauss-Newton model and the Jacobian the
intervals come from."""

import math
from pathlib import Path

import numpy as np
import pytest

from hframe_id.fitting import FitOptions, fit_recordings
from hframe_id.fitting.problem import build_problem
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.fitting.solver import GaussNewton
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.simulated import simulate_recording

MODELS = Path(__file__).resolve().parents[3] / "models"
IDLER = ("J_2", "B_2", "tau_c2")


@pytest.fixture(scope="module")
def one_axis():
    table = load_parameter_file(MODELS / "one-axis-table2.3.yaml")
    u = np.zeros((300, 1))
    u[50:200] = 5.0
    return table, simulate_recording(table, u, seed=3)


@pytest.fixture(scope="module")
def hframe():
    table = load_parameter_file(MODELS / "hframe-8-table4.2.yaml")
    u = np.zeros((300, 2))
    u[50:250] = (-4.0, 2.0)
    return table, simulate_recording(table, u, seed=4)


def test_the_prior_method_frees_the_held_idler_with_its_weight(one_axis):
    table, rec = one_axis
    held = build_problem([rec], table, FitOptions())
    assert not set(IDLER) & set(held.free_names) and not held.prior_names
    problem = build_problem([rec], table, FitOptions(consider_method="prior"))
    # Freed in model order, each with weight 1 / 0.2 (the default +/-20 %) around its start.
    assert problem.free_names == tuple(
        n for n in problem.model.parameter_names if n in held.free_names or n in IDLER
    )
    assert problem.prior_names == IDLER
    weights = dict(zip(problem.free_names, problem.prior_weight, strict=True))
    assert [weights[n] for n in IDLER] == pytest.approx([5.0, 5.0, 5.0])
    # Explicit priors replace the default; a fixed parameter keeps no prior (held exact).
    chosen = build_problem([rec], table, FitOptions(consider_method="prior", consider={"J_2": 0.1}))
    assert chosen.prior_names == ("J_2",) and "B_2" not in chosen.free_names
    fixed = build_problem([rec], table, FitOptions(consider_method="prior", fix=("J_2",)))
    assert fixed.prior_names == ("B_2", "tau_c2") and "J_2" not in fixed.free_names


def test_the_prior_enters_the_cost_the_step_model_and_the_jacobian(hframe):
    table, rec = hframe
    plain = build_problem([rec], table, FitOptions())
    problem = build_problem(
        [rec], table, FitOptions(consider_method="prior", consider={"k_b": 0.2})
    )
    assert problem.free_names == plain.free_names
    j = problem.free_names.index("k_b")
    ms, ms_plain = MultipleShooting(problem).uniform(), MultipleShooting(plain).uniform()
    nodes, _ = ms.initial_nodes(problem.p_initial)
    theta = np.zeros(len(problem.free))
    theta[j] = 0.1
    ev = ms.evaluate(nodes, theta, problem.smoothing)
    ev_plain = ms_plain.evaluate(nodes, theta, plain.smoothing)
    # Cost: + 1/2 (w theta)^2 with w = 1 / 0.2 (rounding only: the same residuals).
    assert ev.cost - ev_plain.cost == pytest.approx(0.5 * (0.1 / 0.2) ** 2, rel=1e-9)
    # Step model: the reduced normal equations gain w^2 on the diagonal and w r in the
    # gradient, and the predicted change along a step the prior's exact quadratic.
    free = np.ones(len(problem.free), dtype=bool)
    gn, gn_plain = GaussNewton(ms), GaussNewton(ms_plain)
    h, g, complete = gn._with_prior(ev, free, gn._linearize(ev, nodes, free), exact=True)
    h0, g0, complete0 = gn_plain._linearize(ev_plain, nodes, free)
    assert h - h0 == pytest.approx(np.diag(np.eye(len(free))[j] * 25.0), abs=1e-9 * h0.max())
    assert g - g0 == pytest.approx(np.eye(len(free))[j] * 25.0 * 0.1, abs=1e-9 * abs(g0).max())
    step = np.zeros(len(free))
    step[j] = -0.1
    assert complete(step)[1] - complete0(step)[1] == pytest.approx(-0.5 * (0.1 / 0.2) ** 2)
    # Jacobian for the intervals: one more row, w at k_b's column, in a Gaussian block.
    jac, residual, blocks = gn.condensed_jacobian(ev, nodes, free)
    jac0, _, _ = gn_plain.condensed_jacobian(ev_plain, nodes, free)
    assert jac.shape[0] == jac0.shape[0] + 1
    column = ms.n_nuisance + j  # after the estimated initial states (none at rest)
    assert np.flatnonzero(jac[-1]).tolist() == [column] and jac[-1, column] == 5.0
    assert residual[-1] == pytest.approx(0.5)
    assert blocks[-1].label == "prior:k_b" and blocks[-1].quantization_step == 0.0


def test_the_map_estimate_moves_by_the_linear_gaussian_shrinkage(hframe):
    table, rec = hframe
    # k_b starts (the prior's mean) 30 % above the truth that made the data. In a linear
    # Gaussian model the prior moves the estimate from the data's own theta_d towards its
    # mean by C / (C + sigma^2) of the way, C the data's (marginal) variance of theta.
    start = table.replace_values(k_b=table.values["k_b"] * 1.3)
    plain = fit_recordings([rec], start, FitOptions())
    result = fit_recordings(
        [rec], start, FitOptions(consider_method="prior", consider={"k_b": 0.2})
    )
    assert result.success and result.prior_names == ("k_b",)
    assert "k_b" in result.free_names and "k_b" not in result.not_identified
    stats = plain.statistics
    j = stats.names.index("k_b")
    variance = stats.covariance_gn[j, j] / stats.noise_scale**2  # (J^T J)^-1, unscaled
    theta_data = math.log(plain.estimates["k_b"].estimate / start.values["k_b"])
    predicted = -theta_data * variance / (variance + 0.2**2)
    measured = math.log(result.estimates["k_b"].estimate / plain.estimates["k_b"].estimate)
    # Measured 1.042e-4 against 1.034e-4: the solvers stop within ~1e-6 in theta (1 % of
    # this shift), the model is not quite linear over 30 %; 5 % holds both, and a prior of
    # the wrong weight (1 / sigma instead of 1 / sigma^2 in the normal equations: x5) fails.
    assert measured == pytest.approx(predicted, rel=0.05)
    assert "Estimated with a prior" in result.held_statement()
    assert "k_b" in result.held_statement() and "with a prior" in result.summary()
