"""The fit report's figures (``fitting.report_figures``): the correlation heat map."""

from types import SimpleNamespace

import numpy as np

from hframe_id.fitting.report_figures import plot_correlation


def _result(correlation, identified_by=None):
    names = ("k_l", "k_r", "J_M1", "B_M1")
    identified_by = identified_by or {}
    estimates = {
        n: SimpleNamespace(key=f"{n} [unit]", identified_by=identified_by.get(n, ())) for n in names
    }
    return SimpleNamespace(free_names=names, correlation=np.array(correlation), estimates=estimates)


#: k_l-k_r strongly, k_r-J_M1 strongly (a chain: one group of three), B_M1 apart.
CHAIN = [
    [1.0, 0.97, 0.5, 0.1],
    [0.97, 1.0, -0.93, 0.0],
    [0.5, -0.93, 1.0, 0.2],
    [0.1, 0.0, 0.2, 1.0],
]


def test_heat_map_has_a_number_in_every_cell_below_the_diagonal(tmp_path, monkeypatch):
    from matplotlib.axes import Axes

    texts = []
    original = Axes.text
    monkeypatch.setattr(
        Axes, "text", lambda ax, *a, **k: texts.append(a[2]) or original(ax, *a, **k)
    )
    plot_correlation(np.array(CHAIN), _result(CHAIN).free_names, tmp_path / "c.png")
    assert (tmp_path / "c.png").stat().st_size > 0
    # the matrix is symmetric with a unit diagonal: each of its 6 values once
    assert sorted(texts) == sorted(["0.97", "0.50", "0.10", "-0.93", "0.00", "0.20"])
