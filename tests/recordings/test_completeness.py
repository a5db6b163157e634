"""Samples kept of those planned (hframe_id.recordings.completeness): the sentence that
inspect, record and the fit report print for an incomplete recording."""

import dataclasses
from pathlib import Path

import pytest

from hframe_id.recordings import read_recording
from hframe_id.recordings.completeness import completeness

REC = Path(__file__).resolve().parents[2] / "datasets" / "4V_xmotion.mcap"


@pytest.fixture(scope="module")
def complete():
    return read_recording(REC)


def _cut(rec, n: int, **changes):
    return dataclasses.replace(
        rec,
        time_s=rec.time_s[:n],
        inputs=rec.inputs[:n],
        outputs=rec.outputs[:n],
        valid=rec.valid[:n],
        signals=rec.signals[:n] if rec.signals is not None else None,
        **changes,
    )


def test_a_complete_run_needs_no_sentence(complete):
    state = completeness(complete)
    assert (state.samples, state.planned, state.missing, state.lost_share) == (1000, 1000, 0, 0.0)
    assert state.statement() is None


def test_an_aborted_run_with_gaps(complete):
    rec = _cut(complete, 700, aborted=True, sequence_gaps=((100, 3), (400, 2)))
    state = completeness(rec)
    assert state.missing == 300 and state.lost_in_gaps == 5
    assert state.statement() == (
        "700 of 1000 planned samples (30.0 % lost): the run was aborted; 5 sample(s) were lost "
        "on the link"
    )


def test_without_a_plan_only_the_gaps_count(complete):
    rec = _cut(complete, 995, events=(), experiment={}, sequence_gaps=((10, 5),))
    state = completeness(rec)
    assert state.planned is None and state.missing == 5 and state.lost_share == 5 / 1000
    assert state.statement() == "995 samples (0.5 % lost): 5 sample(s) were lost on the link"
