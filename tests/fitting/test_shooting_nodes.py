"""Starting values of the shooting nodes (``fitting.shooting_nodes``): from the measurements, or
simulated from the last known node."""

from pathlib import Path

import numpy as np

from hframe_id.fitting import FitOptions
from hframe_id.fitting.problem import build_problem
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.simulated import simulate_recording

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
