"""Starting values of the shooting nodes (``fitting.shooting_nodes``): from the measurements, or
simulated from the last known node."""

from pathlib import Path

import numpy as np
import pytest

from hframe_id.fitting import FitOptions
from hframe_id.fitting.problem import build_problem
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.simulated import simulate_recording
from hframe_id.simulation.open_loop import simulate

MODELS = Path(__file__).resolve().parents[2] / "models"


def test_filling_a_view_without_some_records_windows():
    """A record with no window in a view (it never moves, so the moving-window stages leave
    it out: a 2 V step on a worn rig) is skipped, not an IndexError (issue 25)."""
    table = load_parameter_file(MODELS / "hframe-8-table4.2.yaml")
    u = np.zeros((200, 2))
    u[50:150] = (-4.0, 4.0)
    records = [simulate_recording(table, u, seed=1), simulate_recording(table, 0 * u, seed=2)]
    ms = MultipleShooting(build_problem(records, table, FitOptions(free=("k_l",))))
    nodes, _ = ms.initial_nodes(ms.problem.p_initial)
    first_record = np.flatnonzero(ms.window_experiment == 0)
    view = ms.subset(first_record)
    known = np.zeros(view.n_windows, dtype=bool)
    known[0] = True
    filled = view.fill_nodes(nodes[first_record], known, np.zeros(1), ms.problem.smoothing)
    assert filled.shape == (first_record.size, ms.nx) and np.all(np.isfinite(filled))
    assert np.any(filled[1:, 4:] != 0)  # simulated through the step


@pytest.fixture(scope="module")
def transcription(table, x_step):
    """The 10-sample windows of one 4 V x-motion step from rest, k_l free."""
    options = FitOptions(free=("k_l",)).for_model("hframe-8")
    problem = build_problem([x_step(table, seed=5)], table, options)
    return MultipleShooting(problem, transcription=options.transcription_options)


def test_measured_nodes_take_each_valid_measured_position_and_rest_at_the_start(transcription):
    """Every node but the first takes the measured positions; the first of a record at rest
    the belt-free ones (in its projector's range, near the measured: within a laser's
    noise, 5 um, over r = 0.0194 m: 3e-4 rad) and no speed."""
    ms = transcription
    nodes, velocity = ms.initial_nodes(ms.problem.p_initial)
    exp = ms.problem.experiments[0]
    assert nodes.shape == (ms.n_windows, ms.nx) and velocity.shape == (
        ms.n_windows,
        ms.m + 1,
        ms.nq,
    )
    starts = ms.window_start
    for j, state in enumerate(ms.output_states):  # phi1, phi2, x, y: each a coordinate
        ok = exp.valid[starts, j]
        ok[0] = False
        np.testing.assert_array_equal(nodes[ok, state], exp.measured[starts[ok], j])
        if exp.valid[0, j]:
            assert abs(nodes[0, state] - exp.measured[0, j]) < 1e-3
    projector = ms.node_projector[0]
    np.testing.assert_allclose(projector @ nodes[0], nodes[0], rtol=0, atol=1e-15)
    assert np.all(nodes[0, ms.nq :] == 0.0)  # a record at rest starts without speed
    assert np.any(nodes[:, ms.nq :] != 0.0)  # the differenced rates of the step


def test_unknown_nodes_are_the_simulation_from_the_first(transcription):
    """Every window but the first unknown: the nodes are open_loop.simulate's states at the
    window starts, with the stiffest window's substeps (the same RK4: equal to rounding)."""
    ms = transcription
    problem = ms.problem
    nodes, _ = ms.initial_nodes(problem.p_initial)
    known = np.zeros(ms.n_windows, dtype=bool)
    known[0] = True
    filled = ms.fill_nodes(nodes, known, np.zeros(1), problem.smoothing)
    n_sub = ms.substep_plan(problem.p_initial, problem.smoothing)["stiff"]
    states = simulate(
        ms.model,
        problem.p_initial,
        problem.experiments[0].inputs,
        problem.sample_period_s,
        x0=nodes[0],
        n_substeps=n_sub,
        smoothing=problem.smoothing,
    )
    np.testing.assert_allclose(filled, states[ms.window_start], rtol=1e-12, atol=1e-12)
    assert not np.allclose(filled, nodes)  # not the measured nodes
