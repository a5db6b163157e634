"""The logging section's synthetic record: what it writes, the reader reads back (its valid
laser readings once ran past the measuring range, and `make bench` stopped in a
LogFormatError traceback at the read)."""

from bench.logging import N_MESSAGES, PLANT, _message, _write
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.reader import read_recording
from hframe_id.rig.sim import SimRig


def test_the_synthetic_record_is_read_back_whole(tmp_path):
    path = tmp_path / "bench.mcap"
    rig = SimRig(load_parameter_file(PLANT)).info.metadata()
    messages = [_message(k) for k in range(N_MESSAGES)]
    _write(path, messages, rig)
    recording = read_recording(path)
    assert recording.n_samples == N_MESSAGES and not recording.sequence_gaps
