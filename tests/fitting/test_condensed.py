"""The condensed linearisation of the multiple-shooting problem (``fitting.condensed``): the
single-shooting Jacobian, and the prior's rows in the cost, the step model and the Jacobian."""

from pathlib import Path

import numpy as np
import pytest

from hframe_id.fitting import FitOptions
from hframe_id.fitting.problem import build_problem
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.fitting.solver import GaussNewton
from hframe_id.simulation.open_loop import simulate

MODELS = Path(__file__).resolve().parents[2] / "models"


def test_condensed_jacobian_is_the_single_shooting_jacobian(shooting_setup):
    problem, ms, nodes, _ = shooting_setup
    theta = np.zeros(len(problem.free))
    ev = ms.evaluate(nodes, theta, problem.smoothing)
    gn = GaussNewton(ms)
    jac, residual, blocks = gn.condensed_jacobian(ev, nodes, np.ones(len(problem.free), bool))
    j = problem.free_names.index("k_b")
    h = 1e-6
    outs = []
    for sign in (1, -1):
        th = theta.copy()
        th[j] += sign * h
        p = problem.parameters(th)
        x = simulate(ms.model, p, problem.experiments[0].inputs, 1e-3, x0=nodes[0],
                     n_substeps=ev.n_substeps[1])[:-1]  # fmt: skip
        outs.append(x @ ms.c.T / problem.channel_std)
    fd = (outs[0] - outs[1]) / (2 * h)
    valid = problem.experiments[0].valid
    column = jac[:, ms.n_nuisance + j]  # after the estimated initial states (none at rest)
    # Rows are (window, sample, channel) of the valid samples, i.e. time-major order.
    assert column == pytest.approx(fd[valid], rel=1e-4, abs=1e-3 * np.max(np.abs(fd)))
    assert sum(b.rows.size for b in blocks) == residual.size


def test_the_prior_enters_the_cost_the_step_model_and_the_jacobian(table_and_step):
    table, rec = table_and_step
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
