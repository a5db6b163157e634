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
