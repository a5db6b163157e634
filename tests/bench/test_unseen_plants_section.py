"""The unseen-plants bench section's rows, summary, JSON and command line on made-up trials,
without fitting (``python -m bench.unseen_plants`` runs the fits)."""

import json
import math

import pytest

from bench import unseen_plants as section
from bench.unseen_plants import (
    TABLE_HEADER,
    Matched,
    document,
    plant_row,
    summary_line,
    wall_ratio,
)
from studies.unseen_plants import PlantDraw, TrialError, UnseenTrial


def _trial(label="seed 3", **fields) -> UnseenTrial:
    return UnseenTrial(draw=PlantDraw(label), split="dev", **fields)


PASSED = _trial(
    success=True, wall_time_s=20.0, cost=(0.5, 1.0), held_out_rms_rad=(1.2, 1.0), travel_m=0.14
)
# Training 1.2 x (over 1.05), held out 1.6 x (over 1.5); the solver gave up.
FAILED = _trial(
    "worn", success=False, wall_time_s=60.0, cost=(1.2, 1.0), held_out_rms_rad=(1.6, 1.0)
)
CRASHED = _trial(wall_time_s=5.0, error=TrialError("fit", "ValueError", "bad", "a:1", "b:2"))
EXITED = _trial(error=TrialError("process", "BrokenProcessPool", "exited", "?", "?"))


def test_the_baseline_is_the_median_run():
    matched = Matched((2.5, 9.0, 2.0), (True, True, False))
    assert matched.median_s == 2.5
    assert matched.line() == (
        "matched: six shipped steps, times 2.5, 9.0, 2.0 s, median 2.5 s, success 2/3"
    )


def test_wall_ratio_only_of_fits_that_returned():
    assert wall_ratio(PASSED, 4.0) == 5.0
    assert math.isnan(wall_ratio(CRASHED, 4.0))  # a fit that raised is not a fit's time
    assert math.isnan(wall_ratio(EXITED, 4.0))


def test_rows_fill_the_table():
    columns = TABLE_HEADER.splitlines()[0].count("|")
    rows = [plant_row(t, 4.0) for t in (PASSED, FAILED, CRASHED, EXITED)]
    assert all(row.count("|") == columns for row in rows)
    assert rows[0] == (
        "| seed 3 | dev | 0.14 | 20.0 | 5.0x | 0.500 PASS | 1.200 PASS | yes | PASS |"
    )
    assert rows[1] == "| worn | dev | - | 60.0 | 15.0x | 1.200 FAIL | 1.600 FAIL | no | FAIL |"
    assert rows[2] == (
        "| seed 3 | dev | - | 5.0 | - | - | - | - | FAIL; TRACEBACK in fit: ValueError: bad "
        "at b:2 |"
    )
    assert rows[3].endswith(
        "| - | - | - | - | - | - | FAIL; EXIT in process: BrokenProcessPool: exited at ? |"
    )


def test_summary_counts_passes_and_ratios():
    line = summary_line([PASSED, FAILED, CRASHED, EXITED], 4.0)
    assert line == (
        "unseen plants: wall / matched median 10.0x, max 15.0x (2 fits, matched 4.0 s); "
        "pass 1/4 (training 1/4, held-out 1/4); success 1/4; tracebacks or exits 2"
    )
    assert summary_line([CRASHED], 4.0).startswith("unseen plants: no fit returned; pass 0/1")


def test_the_json_document_is_strict():
    matched = Matched((4.0,), (True,))
    doc = json.loads(json.dumps(document(matched, [PASSED, CRASHED], jobs=1), allow_nan=False))
    assert doc["matched"] == {"times_s": [4.0], "median_s": 4.0, "successes": [True]}
    assert [row["wall_ratio"] for row in doc["rows"]] == [5.0, None]
    assert doc["rows"][0]["passes_training"] and doc["rows"][1]["error"]["where_own"] == "b:2"
    assert doc["summary"] == summary_line([PASSED, CRASHED], 4.0)


def test_command_line_defaults_and_refusals(capsys):
    parser = section.make_parser()
    args = parser.parse_args([])
    assert args.named == ["linear", "lubricated", "worn", "heavy"] and args.seeds == [3, 8, 11]
    assert args.jobs == 1 and args.json is None
    args = parser.parse_args(["--named", "--seeds", "8"])
    assert args.named == [] and args.seeds == [8]
    for argv in (["--seeds", "1042"], ["--seeds", "100"], ["--jobs", "0"], ["--named", "x"]):
        with pytest.raises(SystemExit):
            parser.parse_args(argv)
    assert "not a dev seed" in capsys.readouterr().err
