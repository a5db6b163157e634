"""Which recordings carry each parameter's information (``statistics.information_shares``)."""

from __future__ import annotations

import numpy as np
import pytest

from hframe_id.fitting.statistics import Block, information_shares


def _block(label: str, rows) -> Block:
    rows = np.asarray(rows)
    return Block(label, rows, 1.0, 0.0, np.zeros(rows.size))


def test_shares_are_each_recordings_part_of_a_parameters_information():
    """Columns: one initial state (nuisance), then a and b. a is seen by recording A only;
    b by A (1^2 + 1^2 = 2) and B (2^2 + 1^2 + 1^2 = 6 over its two channels); the prior's
    row on b is not a recording's."""
    jac = np.array(
        [
            [5.0, 1.0, 1.0],  # A:phi1
            [5.0, 3.0, 1.0],  # A:phi2
            [0.0, 0.0, 2.0],  # B:phi1
            [0.0, 0.0, 1.0],  # B:phi2
            [0.0, 0.0, 1.0],  # B:phi2
            [0.0, 0.0, 9.0],  # prior on b
        ]
    )
    blocks = [
        _block("A:phi1", [0]),
        _block("A:phi2", [1]),
        _block("B:phi1", [2]),
        _block("B:phi2", [3, 4]),
        _block("prior:b", [5]),
    ]
    shares = information_shares(jac, blocks, 1, ("a", "b"))
    assert shares["a"] == pytest.approx({"A": 1.0, "B": 0.0})
    assert shares["b"] == pytest.approx({"A": 0.25, "B": 0.75})


def test_a_parameter_no_recording_sees_has_no_share():
    jac = np.zeros((2, 1))
    shares = information_shares(jac, [_block("A:x", [0]), _block("B:x", [1])], 0, ("c",))
    assert shares == {"c": {"A": 0.0, "B": 0.0}}


def test_a_fit_of_two_recordings_says_which_carries_each_parameter(tmp_path):
    """The shipped 2 V x and y steps: every free parameter's shares add up to 1 (within
    rounding), and the report shows them."""
    from hframe_id.fitting import FitOptions, fit_recordings
    from hframe_id.fitting.report_tables import information_lines
    from hframe_id.parameters import load_parameter_file
    from hframe_id.recordings.reader import read_recording
    from hframe_id.resources import dataset_file, model_file

    recordings = [read_recording(dataset_file(f"2V_{axis}motion.mcap")) for axis in "xy"]
    table = load_parameter_file(model_file("hframe-8-table4.2.yaml"))
    result = fit_recordings(recordings, table, FitOptions())
    shares = result.statistics.information_share
    assert set(shares) == set(result.statistics.names)
    for name, share in shares.items():
        assert set(share) == {"2V_xmotion.mcap", "2V_ymotion.mcap"}, name
        assert sum(share.values()) == pytest.approx(1.0, abs=1e-12), name
    lines = information_lines(result)
    assert lines[0] == "## Where each parameter's information comes from"
