"""Which recordings carry each parameter's information, from a whole fit of two shipped
records (``statistics.information_shares``, ``report_tables.information_lines``)."""

import pytest


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
