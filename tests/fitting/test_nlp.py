"""CasADi's NLP solvers (``fitting.nlp``): one-line errors for bad settings, and a record
at rest held to unstretched belts."""

import numpy as np
import pytest

from hframe_id.errors import OptionError
from hframe_id.fitting.nlp import NlpSettings


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("solver", "snopt", "solver must be one of ipopt, sqpmethod, got 'snopt'"),
        ("qp_solver", "gurobi", "qp_solver must be one of qpoases, osqp, qrqp, got 'gurobi'"),
        ("tolerance", 0.0, "tolerance must be a number in (0, 1), got 0.0"),
        ("max_iter", 0, "max_iter must be a whole number in [1, 100000], got 0"),
        ("print_level", 1.5, "print_level must be a whole number in [0, 12], got 1.5"),
    ],
)
def test_bad_settings_give_one_line_errors(field, value, message):
    with pytest.raises(OptionError) as error:
        NlpSettings(**{field: value})
    assert str(error.value) == message
    assert "\n" not in str(error.value)


def test_the_nlp_holds_a_record_at_rest_to_its_rigid_modes(table_and_step):
    """A record at rest: two conditions (4 positions less 2 rigid modes, the velocities fixed
    by their bounds), orthonormal and blind to the rigid modes; IPOPT from 20 % off moves the
    first node only along them, to its constraint tolerance (1e-10, in SI here: the
    conditions act on the node [m, rad]; the test allows 10 x that)."""
    from hframe_id.fitting import FitOptions
    from hframe_id.fitting.nlp import rest_conditions, solve_nlp
    from hframe_id.fitting.problem import build_problem, rigid_modes
    from hframe_id.fitting.shooting import MultipleShooting

    table, step = table_and_step
    problem = build_problem([step], table, FitOptions(free=("k_b", "M_cart")))
    ms = MultipleShooting(problem).uniform()
    (window, rows), *others = rest_conditions(ms)
    assert window == 0 and not others and rows.shape == (2, ms.nx)
    np.testing.assert_allclose(rows @ rows.T, np.eye(2), rtol=0, atol=1e-15)
    modes = rigid_modes(ms.model, problem.p_initial)
    np.testing.assert_allclose(rows[:, : ms.nq] @ modes, 0.0, rtol=0, atol=1e-15)
    assert not rows[:, ms.nq :].any()
    nodes, _ = ms.initial_nodes(problem.p_initial)
    outcome = solve_nlp(ms, nodes, np.log([1.2, 0.8]), np.ones(2, dtype=bool), problem.smoothing)
    assert np.any(outcome.nodes[0, : ms.nq] != nodes[0, : ms.nq])
    np.testing.assert_allclose(rows @ outcome.nodes[0], rows @ nodes[0], rtol=0, atol=1e-9)
    assert not outcome.nodes[0, ms.nq :].any()


def test_a_start_too_stiff_for_max_substeps_is_not_solved(table_and_step):
    """With max_substeps below what stability needs at the start (Table 4.2: 16-17), the NLP
    is neither built nor solved (its transcription would need that count in every window):
    not converged, saying why, the start returned as given."""
    import dataclasses

    from hframe_id.fitting import FitOptions
    from hframe_id.fitting.nlp import solve_nlp
    from hframe_id.fitting.problem import build_problem
    from hframe_id.fitting.shooting import MultipleShooting

    table, step = table_and_step
    problem = build_problem([step], table, FitOptions(free=("k_b", "M_cart")))
    ms = MultipleShooting(problem).uniform()
    refusing = MultipleShooting(
        problem, transcription=dataclasses.replace(ms.transcription, max_substeps=10)
    ).uniform()
    nodes, _ = refusing.initial_nodes(problem.p_initial)
    theta = np.zeros(2)
    outcome = solve_nlp(refusing, nodes, theta, np.ones(2, dtype=bool), problem.smoothing)
    assert not outcome.converged and outcome.iterations == 0
    assert "more than max_substeps 10" in outcome.message
    assert outcome.substeps > 10 and outcome.build_time_s == 0.0
    np.testing.assert_array_equal(outcome.theta, theta)


@pytest.mark.parametrize(
    ("solver", "status", "small"),
    [
        ("sqpmethod", "Search_Direction_Becomes_Too_Small", True),
        ("sqpmethod", "Maximum_Iterations_Exceeded", False),
        ("ipopt", "Search_Direction_Becomes_Too_Small", False),  # IPOPT's own failure
    ],
)
def test_only_sqpmethods_small_search_direction_is_a_small_step_stop(solver, status, small):
    from hframe_id.fitting.nlp import stopped_on_small_step

    settings = NlpSettings(solver=solver)
    assert stopped_on_small_step(settings, {"return_status": status, "success": False}) is small
