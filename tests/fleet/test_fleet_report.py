"""The fleet report's history plots (``hframe_id.fleet.report``): a view that shows the changes."""

from __future__ import annotations

import math

import pandas as pd
import pytest
from matplotlib.figure import Figure

from hframe_id.atomic import Staging
from hframe_id.fleet.report import change_view, plot_histories


def test_the_view_holds_every_change_and_the_threshold_with_a_tenth_to_spare():
    assert change_view([-30.0, 5.0, 70.0], 10.0) == pytest.approx((-40.0, 80.0))
    assert change_view([2.0], 10.0) == pytest.approx((-12.0, 12.0))
    assert change_view([math.inf, 20.0], 10.0) == pytest.approx((-13.0, 23.0))


def _runs(k_l, identified, low, high):
    """Three weekly ``ok`` runs of one rig: k_l [N/m], whether identified, 95 % bounds."""
    return pd.DataFrame(
        {
            "rig": "rig-01",
            "run_time": [
                pd.Timestamp("2026-01-05", tz="UTC") + pd.Timedelta(weeks=w) for w in range(3)
            ],
            "status": "ok",
            "k_l [N/m]": k_l,
            "k_l std [N/m]": [0.01 * v for v in k_l],
            "k_l ci95 low [N/m]": low,
            "k_l ci95 high [N/m]": high,
            "k_l identified": identified,
        }
    )


def test_a_history_is_drawn_at_the_scale_of_its_changes_with_unjudged_runs_hollow(
    tmp_path, monkeypatch
):
    """A poorly determined run's interval of 1e22 % (a realistic fleet's k_b) is cut at the
    view's edge; the run that did not identify the parameter is drawn hollow."""
    drawn = {}
    save = Figure.savefig

    def keep(fig, path, **kwargs):
        drawn["axes"] = fig.axes[0]
        save(fig, path, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    frame = _runs([100.0, 130.0, 70.0], [True, False, True], [99.0, 0.0, 69.0], [101.0, 1e22, 71.0])
    staging = Staging()
    paths = plot_histories(frame, 0.1, tmp_path / "plots", staging)
    staging.commit()
    assert [p.name for p in paths] == ["k_l.png"] and paths[0].is_file()
    ax = drawn["axes"]
    assert ax.get_ylim() == pytest.approx((-36.0, 36.0))
    hollow = [line for line in ax.get_lines() if line.get_markerfacecolor() == "white"]
    assert len(hollow) == 1 and list(hollow[0].get_ydata()) == pytest.approx([30.0])
    assert hollow[0].get_label() == "not identified (not judged)"
