"""The multiple-shooting transcription (``fitting.shooting``): its windows reproduce the
simulator, and its sensitivities and residual Jacobians are exact."""

from pathlib import Path

import numpy as np
import pytest
from servo_outputs import servo_model_file, servo_recording, start

from hframe_id.fitting import FitOptions
from hframe_id.fitting.problem import build_problem
from hframe_id.fitting.shooting import MultipleShooting

MODELS = Path(__file__).resolve().parents[2] / "models"


@pytest.fixture(scope="module")
def servo(tmp_path_factory):
    """``servo(variant)``: the model name of a DC servo variant (``servo_outputs``)."""
    folder = tmp_path_factory.mktemp("servo")
    return lambda variant: servo_model_file(folder, variant)[0]


def test_windows_reproduce_the_simulator(shooting_setup):
    problem, ms, nodes, states = shooting_setup
    ev = ms.evaluate(nodes, np.zeros(len(problem.free)), problem.smoothing)
    # Same RK4, same substeps: the window ends are the next nodes to rounding.
    assert np.max(np.abs(ev.x_end[:-1] - nodes[1:])) < 1e-10
    assert np.max(np.abs(ms.defects(ev, nodes))) < 1e-3  # in noise units


def test_sensitivities_match_finite_differences(shooting_setup):
    problem, ms, nodes, _ = shooting_setup
    theta = np.zeros(len(problem.free))
    ev = ms.evaluate(nodes, theta, problem.smoothing)
    w = 12  # a window in motion
    for j in (0, 3, 5, 11, 15):  # k_l, J_M1, M_cart, tau_cM1 (Coulomb), g_2
        h = 1e-6
        plus = theta.copy()
        plus[j] += h
        minus = theta.copy()
        minus[j] -= h
        end_p = ms.evaluate(nodes, plus, problem.smoothing).x_end[w]
        end_m = ms.evaluate(nodes, minus, problem.smoothing).x_end[w]
        fd = (end_p - end_m) / (2 * h)
        exact = ev.b_end[w, :, j]
        # Central differences are good to ~1e-6 relative of the largest entry here.
        assert np.max(np.abs(fd - exact)) <= 1e-5 * np.max(np.abs(exact)) + 1e-12, j
    for i in (0, 2, 4, 6):
        h = 1e-7
        plus, minus = nodes.copy(), nodes.copy()
        plus[w, i] += h
        minus[w, i] -= h
        fd = (
            ms.evaluate(plus, theta, problem.smoothing).x_end[w]
            - ms.evaluate(minus, theta, problem.smoothing).x_end[w]
        ) / (2 * h)
        assert np.max(np.abs(fd - ev.a_end[w, :, i])) <= 1e-5 * np.max(np.abs(fd)) + 1e-9, i


def test_the_residual_jacobians_of_a_general_output_map_are_exact(servo):
    name = servo("shipped")
    options = FitOptions(verbose=0, shooting_interval=20).for_model(start(name).variant)
    problem = build_problem([servo_recording(name, 3, n=300)], start(name), options)
    ms = MultipleShooting(problem, transcription=options.transcription_options)
    assert ms._output_index is None  # the current is no state: the general output map
    nodes, _ = ms.initial_nodes(problem.p_initial)
    theta = np.array([0.1, -0.2, 0.05, 0.03])  # J, B, tau_c, g moved off the start
    nodes = nodes + np.array([0.0, 3.0])  # and the speeds off the measurements
    ev = ms.evaluate(nodes, theta, problem.smoothing)
    # Central differences (step 1e-6 in log p, 1e-4 rad/s): truncation ~h^2 / 6 f''' and
    # round-off ~1e-16 / h relative, both below 1e-6 of the largest entry; the tolerance is
    # 1e-5 of it.
    for i in range(theta.size):
        h = 1e-6
        up = ms.evaluate(nodes, theta + h * np.eye(theta.size)[i], problem.smoothing)
        down = ms.evaluate(nodes, theta - h * np.eye(theta.size)[i], problem.smoothing)
        numeric = (up.residual - down.residual) / (2 * h)
        scale = np.abs(numeric).max()
        np.testing.assert_allclose(ev.jac_theta[..., i], numeric, rtol=0, atol=1e-5 * scale)
    h = 1e-4
    step = np.zeros_like(nodes)
    step[:, 1] = h
    up = ms.evaluate(nodes + step, theta, problem.smoothing, derivatives=False)
    down = ms.evaluate(nodes - step, theta, problem.smoothing, derivatives=False)
    numeric = (up.residual - down.residual) / (2 * h)
    np.testing.assert_allclose(
        ev.jac_node[..., 1], numeric, rtol=0, atol=1e-5 * np.abs(numeric).max()
    )


def test_a_record_at_rest_starts_with_unstretched_belts(table, x_step, in_motion):
    """The first node of a record at rest moves only along the rigid modes (x, y with the
    motors turning as the belts carry them: 2 of hframe-8's 4 positions), with no speed: its
    projector is symmetric and idempotent, of rank 2, and every direction in its range
    stretches no belt (the stiffness matrix annuls it); a record in motion estimates all 8
    entries."""
    from hframe_id.fitting.problem import rigid_modes

    step = x_step(table, seed=5)
    problem = build_problem([step, in_motion(step, 150)], table, FitOptions())
    ms = MultipleShooting(problem)
    rest, moving = (ms.node_projector[i] for i in ms.first_window)
    # Rounding of M M^T from an orthonormal SVD basis: 1e-15 of its unit entries.
    np.testing.assert_allclose(rest, rest.T, rtol=0, atol=1e-15)
    np.testing.assert_allclose(rest @ rest, rest, rtol=0, atol=1e-15)
    assert round(np.trace(rest)) == 2 and not rest[:, ms.nq :].any()
    modes = rigid_modes(ms.model, problem.p_initial)
    np.testing.assert_allclose(rest[: ms.nq, : ms.nq] @ modes, modes, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(moving, np.eye(ms.nx))
    np.testing.assert_array_equal(ms.fixed_node[ms.first_window[0]], [False] * 4 + [True] * 4)
    assert [b.shape for b in ms.initial_state_bases] == [(8, 2), (8, 8)]
    assert ms.n_nuisance == 10
    for basis, projector in zip(ms.initial_state_bases, (rest, moving), strict=True):
        np.testing.assert_allclose(basis @ basis.T, projector, rtol=0, atol=1e-15)


def test_a_gauss_newton_step_keeps_the_start_at_rest(table_and_step):
    """From a start off the data (k_b and M_cart 20 % off), every step moves the first node
    of a record at rest within its projector's range: belts unstretched to rounding (the
    solve is projected again: 1e-8 m had leaked, ``condensed._restrict``)."""
    from hframe_id.fitting.builtin_solvers import GAUSS_NEWTON
    from hframe_id.fitting.solver import GaussNewton, SolverState
    from hframe_id.fitting.solvers import Stage

    table, step = table_and_step
    options = FitOptions(free=("k_b", "M_cart"))
    problem = build_problem([step], table, options)
    ms = MultipleShooting(problem).uniform()
    nodes, _ = ms.initial_nodes(problem.p_initial)
    nodes = ms.fill_nodes(nodes, np.eye(1, ms.n_windows, dtype=bool)[0], np.zeros(2),
                          problem.smoothing)  # fmt: skip
    state = SolverState(nodes, np.log([1.2, 0.8]), np.ones(2, dtype=bool))
    solver_options = FitOptions(max_iterations=5).solver_options
    GAUSS_NEWTON.solve(Stage("all", GaussNewton(ms), state, solver_options, {"radius": 0.5}))
    first = state.nodes[0]
    assert np.any(first != nodes[0])  # the rigid amplitudes were estimated
    off = (np.eye(ms.nx) - ms.node_projector[0]) @ first
    assert np.max(np.abs(off)) < 1e-15
