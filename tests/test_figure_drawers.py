"""Figures drawn here or in worker processes: the same files, failures raised by ``finish``,
nothing written after ``finish`` or ``discard`` returns."""

import numpy as np
import pytest

from hframe_id.figure_drawers import InlineDrawer, ProcessDrawer
from hframe_id.fitting.report_figures import ExperimentSignals, plot_correlation, plot_experiment

NAMES = ("k_l", "k_r", "J_M1")
CORRELATION = np.array([[1.0, 0.95, 0.1], [0.95, 1.0, -0.2], [0.1, -0.2, 1.0]])


def _signals():
    t = np.linspace(0.0, 1.0, 200)
    measured = np.column_stack([np.sin(t), 1e-3 * t])
    measured[5, 0] = np.nan  # a sample that is not valid
    return ExperimentSignals(
        time_s=t,
        names=("phi1", "x"),
        units=("rad", "m"),
        measured=measured,
        fitted=measured + 1e-6,
        reference=None,
        title="step.mcap",
    )


@pytest.mark.parametrize("make", [InlineDrawer, ProcessDrawer])
def test_both_drawers_write_the_same_figures(tmp_path, make):
    with make() as drawer:
        drawer.draw(plot_correlation, CORRELATION, NAMES, tmp_path / "c.png")
        drawer.draw(plot_experiment, _signals(), "Table 4.2", tmp_path / "e.png")
        drawer.finish()
    for name in ("c.png", "e.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_worker_failure_is_raised_by_finish_after_every_figure_is_done(tmp_path):
    with ProcessDrawer() as drawer:
        drawer.draw(plot_correlation, CORRELATION, NAMES, tmp_path / "missing" / "c.png")
        drawer.draw(plot_correlation, CORRELATION, NAMES, tmp_path / "ok.png")
        with pytest.raises(FileNotFoundError):
            drawer.finish()
        # the other figure was drawn before finish raised: no worker writes afterwards
        assert (tmp_path / "ok.png").exists()
        drawer.discard()  # nothing pending any more
