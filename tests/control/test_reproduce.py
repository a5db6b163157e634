"""Chapter 5 reproduction: what this simulator honestly achieves against Tables 5.1-5.6.

Measured with models/hframe-8-table4.2.yaml (``make reproduce``, reports/reproduction):

| gain set       | leg-1 overshoot | leg-3 overshoot |
| PID 150/100/4  | 0.473 mm (-19 %) | 0.434 mm (-14 %) |
| PID 150/1500/4 | 0.963 mm (-37 %) | 0.986 mm (-36 %) |
| PD 150/4       | 0.412 mm (-8 %)  | 0.412 mm (-9 %)  |
| PD 175/4       | 0.463 mm (-16 %) | 0.463 mm (-16 %) |

The issue's target (leg-1 and leg-3 overshoots within 30 % for all four gain sets) is met for
three; the high-integral PID stays 36-37 % below the thesis (report: not explained by the
friction law, the friction levels or a computation delay). The asserted bands are the measured
values with room for round-off and nothing more, so any change of the model, the controller or
the metrics that moves them shows up here. The ranking by Table 5.6's score is the thesis's.
"""

from pathlib import Path

import pytest

from hframe_id.cli import main
from hframe_id.control.reproduction import THESIS_TABLES, Reproduction, reproduce, thesis_score
from hframe_id.parameters import load_parameter_file

MODELS = Path(__file__).resolve().parents[2] / "models"


@pytest.fixture(scope="module")
def reproduction():
    return reproduce(load_parameter_file(MODELS / "hframe-8-table4.2.yaml"), sensitivity=False)


def test_thesis_ranking_from_table_5_6():
    # Table 5.6's percentages give PD 175/4 87.8 %, PD 150/4 90.8 %, PID 150/1500/4 187.5 %.
    scores = {t.label: round(100 * thesis_score(t), 1) for t in THESIS_TABLES}
    assert scores == {"PID 150/100/4": 100.0, "PID 150/1500/4": 187.5, "PD 150/4": 90.8,
                      "PD 175/4": 87.8}  # fmt: skip
    assert Reproduction.thesis_ranking() == ["PD 175/4", "PD 150/4", "PID 150/100/4",
                                             "PID 150/1500/4"]  # fmt: skip


@pytest.mark.parametrize(
    ("label", "low", "high"),
    [
        ("PID 150/100/4", -0.20, -0.13),
        ("PID 150/1500/4", -0.38, -0.35),
        ("PD 150/4", -0.10, -0.07),
        ("PD 175/4", -0.17, -0.15),
    ],
)
def test_leg1_and_leg3_overshoot_deviation(reproduction, label, low, high):
    row = next(r for r in reproduction.rows if r.thesis.label == label)
    for leg in (1, 3):
        assert low <= row.overshoot_deviation(leg) <= high


def test_three_of_four_gain_sets_within_30_percent(reproduction):
    assert reproduction.within_tolerance() == {
        "PID 150/100/4": True,
        "PID 150/1500/4": False,  # -37 %: documented gap (module docstring, report)
        "PD 150/4": True,
        "PD 175/4": True,
    }


def test_same_ranking_as_table_5_6(reproduction):
    assert reproduction.ranking() == reproduction.thesis_ranking()


def test_leg2_undershoots_as_in_the_thesis(reproduction):
    for row in reproduction.rows:
        if row.thesis.ki != 1500:  # Table 5.3 prints an overshoot for leg 2
            assert row.metrics[1].overshoot_m < 0


@pytest.mark.integration
def test_reproduce_command_writes_report_with_plots(tmp_path, capsys):
    out = tmp_path / "reproduction"
    assert main(["reproduce", "--out", str(out), "--no-sensitivity"]) == 0
    report = (out / "report.md").read_text()
    for table in ("Table 5.1", "Table 5.3", "Table 5.4", "Table 5.5", "Table 5.6", "Discussion"):
        assert table in report
    images = sorted(p.name for p in (out / "plots").iterdir())
    assert len(images) == 8
    assert "same as Table 5.6" in capsys.readouterr().out


@pytest.mark.integration
def test_reproduce_rejects_a_one_axis_file(tmp_path, capsys):
    code = main(["reproduce", "--out", str(tmp_path / "r"), "--params",
                 str(MODELS / "one-axis-table2.3.yaml")])  # fmt: skip
    assert code == 2
    assert "needs an H-frame model" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()
