"""The fit report's figures (``fitting.report_figures``): the correlation heat map."""

import numpy as np
from correlated_results import CHAIN, correlated_result

from hframe_id.fitting.report_figures import plot_correlation


def test_heat_map_has_a_number_in_every_cell_below_the_diagonal(tmp_path, monkeypatch):
    from matplotlib.axes import Axes

    texts = []
    original = Axes.text
    monkeypatch.setattr(
        Axes, "text", lambda ax, *a, **k: texts.append(a[2]) or original(ax, *a, **k)
    )
    plot_correlation(np.array(CHAIN), correlated_result(CHAIN).free_names, tmp_path / "c.png")
    assert (tmp_path / "c.png").stat().st_size > 0
    # the matrix is symmetric with a unit diagonal: each of its 6 values once
    assert sorted(texts) == sorted(["0.97", "0.50", "0.10", "-0.93", "0.00", "0.20"])
