"""Log format v1: writing, reading, validation errors, salvage of unfinished files."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from hframe_id.errors import LogFormatError, OptionError
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings import log_format as fmt
from hframe_id.recordings.reader import (
    SequenceGapWarning,
    TruncatedRecordingWarning,
    read_log,
    read_recording,
)
from hframe_id.recordings.sensors import SensorModel
from hframe_id.recordings.simulated import simulate_recording
from hframe_id.recordings.writer import LogWriter, partial_path
from hframe_id.rig.logger import RunOptions, run_experiment
from hframe_id.rig.protocols import PulseProtocol, StepProtocol
from hframe_id.rig.sim import SimRig

MODELS = Path(__file__).resolve().parents[2] / "models"
HFRAME = MODELS / "hframe-8-table4.2.yaml"
ONE_AXIS = MODELS / "one-axis-table2.3.yaml"


def record(path: Path, params_file: Path, protocol, seed: int = 3, **rig_options) -> Path:
    rig = SimRig(load_parameter_file(params_file), seed=seed, paced=False, **rig_options)
    # Chunks by sample time only: wall-clock flushes made the chunk count (which the salvage
    # tests count on) depend on the machine's load.
    run_experiment(rig, protocol, RunOptions(out=path, handle_signals=False, reproducible=True))
    return path


@pytest.fixture(scope="module")
def hframe_file(tmp_path_factory) -> Path:
    # -6 V y-motion for 0.6 s: the y laser leaves its range at ~0.3 s (section 3.4).
    path = tmp_path_factory.mktemp("rec") / "y.mcap"
    return record(path, HFRAME, StepProtocol((-6.0, -6.0), 0.5, 0.6, 0.05))


def good_sample(sequence: int, **changes) -> dict:
    message = {
        "sequence": sequence,
        "device_time_us": 1000 * sequence,
        "u1_V": 1.0,
        "u2_V": None,
        "applied1_V": 1.0,
        "applied2_V": None,
        "encoder1_counts": sequence,
        "encoder2_counts": None,
        "phi1_rad": sequence * 1e-5,
        "phi2_rad": None,
        "laser_x_m": 0.001,
        "laser_x_valid": True,
        "laser_y_m": None,
        "laser_y_valid": None,
        "limit_x_min": False,
        "limit_x_max": False,
        "limit_y_min": None,
        "limit_y_max": None,
        "command_sequence": sequence - 1 if sequence else None,
        "watchdog": False,
    }
    message.update(changes)
    return message


RIG = {
    "variant": "one-axis", "backend": "sim", "sample_period_s": 0.001, "inputs": ["u1"],
    "outputs": ["phi1", "x"], "encoder_counts_per_rev": 321084, "dac_bits": 12,
    "dac_min_v": -10.0, "dac_max_v": 10.0, "laser_min_m": -0.05, "laser_max_m": 0.05,
}  # fmt: skip
EXPERIMENT = {
    "format_version": "1.0", "protocol": "step", "start_time": "2025-01-01T00:00:00+00:00",
    "operator": "test", "software_version": "hframe-id test",
}  # fmt: skip


def craft(path: Path, messages, rig=None, experiment=None) -> Path:
    """A file written by the real writer with arbitrary (possibly wrong) content."""
    writer = LogWriter(path, rig or RIG, experiment or EXPERIMENT, start_time_ns=0)
    for message in messages:
        writer.sample(message["device_time_us"], message)
    writer.finish()
    return path


# -- round trip --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("params_file", "protocol"),
    [
        (HFRAME, StepProtocol((-6.0, 6.0), 0.1, 0.15, 0.02)),
        (ONE_AXIS, PulseProtocol(10.0, 0.1, 0.15, 0.02)),
    ],
)
def test_sim_rig_recording_equals_batch_simulation(tmp_path, params_file, protocol):
    """Same seed, same inputs: the logged sim rig and simulate_recording agree exactly."""
    params = load_parameter_file(params_file)
    recording = read_recording(record(tmp_path / "r.mcap", params_file, protocol, seed=11))
    batch = simulate_recording(params, protocol.table(1e-3), seed=11)
    assert recording.output_names == batch.output_names
    assert recording.input_names == batch.input_names
    np.testing.assert_array_equal(recording.inputs, batch.inputs)
    # Float round-off only: the rig steps one sample at a time, the batch path maps them.
    np.testing.assert_allclose(recording.outputs, batch.outputs, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(recording.valid, batch.valid)
    np.testing.assert_allclose(recording.time_s, batch.time_s, rtol=0, atol=1e-12)
    assert recording.truth is not None and recording.truth.values == params.values


def test_recording_content(hframe_file):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rec = read_recording(hframe_file)
    assert rec.variant == "hframe-8"
    assert rec.n_samples == 600 and rec.sample_period_s == 0.001
    assert rec.output_names == ("phi1", "phi2", "x", "y")
    assert not rec.aborted and not rec.truncated and rec.sequence_gaps == ()
    assert [e["kind"] for e in rec.events] == ["start", "stop"]
    assert rec.rig["encoder_counts_per_rev"] == 321084 and rec.rig["backend"] == "sim"
    assert rec.experiment["format_version"] == "1.0"
    assert rec.experiment["protocol.v1_V"] == -6.0
    y = rec.output_names.index("y")
    # The y laser leaves its range and then holds its last valid value, marked invalid.
    assert rec.valid[:, y].any() and not rec.valid[:, y].all()
    first_invalid = int(np.argmax(~rec.valid[:, y]))
    assert np.all(rec.outputs[first_invalid:, y] == rec.outputs[first_invalid - 1, y])
    frame = rec.to_dataframe()
    assert list(frame.columns[:2]) == ["u1 [V]", "u2 [V]"] and len(frame) == 600


def test_any_mcap_reader_opens_it_and_messages_match_their_schemas(hframe_file):
    with open(hframe_file, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None
        validators = {
            cid: jsonschema.Draft202012Validator(json.loads(summary.schemas[ch.schema_id].data))
            for cid, ch in summary.channels.items()
        }
        counts: dict[str, int] = {}
        for _, channel, message in reader.iter_messages():
            validators[channel.id].validate(json.loads(message.data))
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    assert counts[fmt.SAMPLE_TOPIC] == 600 and counts[fmt.EVENT_TOPIC] == 2
    assert counts[fmt.STATUS_TOPIC] >= 6
    assert set(metadata) == {"rig", "experiment"}
    assert all(isinstance(v, str) for m in metadata.values() for v in m.values())
    assert metadata["rig"]["inputs"] == "u1,u2"


def test_log_time_is_the_sample_time(hframe_file):
    log = read_log(hframe_file)
    times = [t for t, _ in log.messages[fmt.SAMPLE_TOPIC]]
    start = times[0]
    assert [t - start for t in times[:3]] == [0, 1_000_000, 2_000_000]


def test_nan_is_written_as_null(tmp_path):
    # A laser range that excludes the start position: no valid reading yet, so no value.
    sensors = SensorModel(laser_min_m=0.01, laser_max_m=0.05)
    path = tmp_path / "n.mcap"
    rig = SimRig(load_parameter_file(ONE_AXIS), seed=1, paced=False, sensors=sensors)
    run_experiment(rig, PulseProtocol(5.0, 0.01, 0.02, 0.0), RunOptions(out=path))
    first = json.loads(read_log(path).messages[fmt.SAMPLE_TOPIC][0][1])
    assert first["laser_x_m"] is None and first["laser_x_valid"] is False
    rec = read_recording(path)
    assert np.isnan(rec.outputs[0, 1]) and not rec.valid[0, 1]


# -- errors ------------------------------------------------------------------------------------


def test_empty_file(tmp_path):
    (tmp_path / "e.mcap").write_bytes(b"")
    with pytest.raises(LogFormatError, match=r"e\.mcap: empty file"):
        read_recording(tmp_path / "e.mcap")


def test_not_mcap(tmp_path):
    (tmp_path / "t.mcap").write_text("time,u1\n0,1\n")
    with pytest.raises(LogFormatError, match=r"t\.mcap: not an MCAP file"):
        read_recording(tmp_path / "t.mcap")


def test_missing_file(tmp_path):
    with pytest.raises(LogFormatError, match="no such file"):
        read_recording(tmp_path / "nope.mcap")


def test_other_schema(tmp_path):
    path = tmp_path / "o.mcap"
    with open(path, "wb") as stream:
        writer = Writer(stream)
        writer.start()
        schema = writer.register_schema("foo.Pose", "jsonschema", b"{}")
        channel = writer.register_channel(fmt.SAMPLE_TOPIC, "json", schema)
        writer.add_message(channel, log_time=0, data=b"{}", publish_time=0)
        writer.finish()
    with pytest.raises(LogFormatError, match=r"o\.mcap: /rig/sample has schema 'foo.Pose'"):
        read_recording(path)


def test_no_sample_channel(tmp_path):
    path = tmp_path / "c.mcap"
    with open(path, "wb") as stream:
        writer = Writer(stream)
        writer.start()
        schema = writer.register_schema("foo.Pose", "jsonschema", b"{}")
        channel = writer.register_channel("/pose", "json", schema)
        writer.add_message(channel, log_time=0, data=b"{}", publish_time=0)
        writer.finish()
    with pytest.raises(LogFormatError, match=r"no /rig/sample channel.*/pose"):
        read_recording(path)


def test_unknown_major_version(tmp_path):
    path = craft(
        tmp_path / "v.mcap", [good_sample(0)], experiment={**EXPERIMENT, "format_version": "2.0"}
    )
    with pytest.raises(LogFormatError, match=r"v\.mcap: unknown log format version '2.0'"):
        read_recording(path)


def test_newer_minor_version_is_read(tmp_path):
    path = craft(tmp_path / "m.mcap", [good_sample(0), good_sample(1)],
                 experiment={**EXPERIMENT, "format_version": "1.7"})  # fmt: skip
    assert read_recording(path).n_samples == 2


def test_missing_metadata_key(tmp_path):
    rig = {k: v for k, v in RIG.items() if k != "sample_period_s"}
    path = craft(tmp_path / "k.mcap", [good_sample(0)], rig=rig)
    with pytest.raises(LogFormatError, match="rig metadata lacks sample_period_s"):
        read_recording(path)


def test_missing_field(tmp_path):
    broken = good_sample(1)
    del broken["laser_x_m"]
    path = craft(tmp_path / "f.mcap", [good_sample(0), broken])
    with pytest.raises(LogFormatError, match=r"f\.mcap: sample 1 lacks field\(s\) laser_x_m"):
        read_recording(path)


def test_wrong_type(tmp_path):
    path = craft(tmp_path / "w.mcap", [good_sample(0), good_sample(1, encoder1_counts="7")])
    with pytest.raises(LogFormatError, match="sample 1: encoder1_counts must be an integer"):
        read_recording(path)


def test_first_sample_checked_against_schema(tmp_path):
    path = craft(tmp_path / "s.mcap", [good_sample(0, extra=1)])
    with pytest.raises(LogFormatError, match="does not match the sample schema"):
        read_recording(path)


def test_time_must_increase(tmp_path):
    samples = [good_sample(0), good_sample(1), good_sample(2, device_time_us=1000)]
    path = craft(tmp_path / "t.mcap", samples)
    with pytest.raises(LogFormatError, match="device_time_us must increase strictly.*sample 2"):
        read_recording(path)


def test_non_finite_command(tmp_path):
    path = craft(tmp_path / "u.mcap", [good_sample(0), good_sample(1, u1_V=None)])
    with pytest.raises(LogFormatError, match="sample 1: u1_V must be a number, got None"):
        read_recording(path)


def test_valid_laser_needs_a_value(tmp_path):
    path = craft(tmp_path / "l.mcap", [good_sample(0, laser_x_m=None)])
    with pytest.raises(LogFormatError, match="laser_x_m is None although laser_x_valid is true"):
        read_recording(path)


def test_sequence_gaps_are_reported(tmp_path):
    samples = [good_sample(k) for k in (0, 1, 2, 5, 6, 8)]
    path = craft(tmp_path / "g.mcap", samples)
    with pytest.warns(SequenceGapWarning, match="3 sample.s. lost in 2 gap"):
        rec = read_recording(path)
    assert rec.sequence_gaps == ((3, 2), (5, 1))
    np.testing.assert_allclose(rec.time_s, [0, 0.001, 0.002, 0.005, 0.006, 0.008])


def test_invalid_laser_samples_are_masked(tmp_path):
    samples = [good_sample(0), good_sample(1, laser_x_valid=False), good_sample(2)]
    rec = read_recording(craft(tmp_path / "i.mcap", samples))
    assert rec.valid[:, 1].tolist() == [True, False, True]
    assert rec.valid[:, 0].all()


# -- unfinished files --------------------------------------------------------------------------


def chunk_ends(path: Path) -> list[int]:
    """Byte offsets just after each chunk's message indexes (where a flush ended)."""
    with open(path, "rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    return sorted(
        i.chunk_start_offset + i.chunk_length + i.message_index_length
        for i in summary.chunk_indexes
    )


def test_truncated_file_is_salvaged_to_its_last_complete_chunk(hframe_file, tmp_path):
    data = hframe_file.read_bytes()
    ends = chunk_ends(hframe_file)
    assert len(ends) == 6  # 100 ms of samples per chunk
    cut = tmp_path / "cut.mcap.partial"
    cut.write_bytes(data[: ends[2] + 57])  # three chunks and a bit of the fourth
    with pytest.warns(TruncatedRecordingWarning, match=r"recovered 300 samples \(0.299 s\)"):
        rec = read_recording(cut)
    full = read_recording(hframe_file)
    assert rec.truncated and rec.n_samples == 300
    np.testing.assert_array_equal(rec.outputs, full.outputs[:300])
    assert rec.truth is not None  # metadata and attachments precede the chunks


def test_file_cut_at_a_chunk_boundary(hframe_file, tmp_path):
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(hframe_file.read_bytes()[: chunk_ends(hframe_file)[0]])
    with pytest.warns(TruncatedRecordingWarning, match="recovered 100 samples"):
        assert read_recording(cut).n_samples == 100


def test_corrupt_chunk_stops_the_salvage(hframe_file, tmp_path):
    data = bytearray(hframe_file.read_bytes())
    ends = chunk_ends(hframe_file)
    data[ends[1] + 200] ^= 0xFF  # inside the third chunk's compressed data
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    with pytest.warns(TruncatedRecordingWarning, match="corrupt record"):
        assert read_recording(bad).n_samples == 200


def test_nothing_to_recover(hframe_file, tmp_path):
    with open(hframe_file, "rb") as stream:
        first_chunk = min(
            i.chunk_start_offset for i in make_reader(stream).get_summary().chunk_indexes
        )
    cut = tmp_path / "early.mcap"
    cut.write_bytes(hframe_file.read_bytes()[: first_chunk + 100])
    with pytest.raises(LogFormatError, match="no complete chunk, nothing to recover"):
        read_recording(cut)


# -- writer ------------------------------------------------------------------------------------


def test_writer_uses_a_partial_file_until_finished(tmp_path):
    path = tmp_path / "w.mcap"
    writer = LogWriter(path, RIG, EXPERIMENT, start_time_ns=0)
    assert partial_path(path).exists() and not path.exists()
    writer.sample(0, good_sample(0))
    writer.finish()
    assert path.exists() and not partial_path(path).exists()


def test_writer_refuses_to_overwrite(tmp_path):
    path = craft(tmp_path / "x.mcap", [good_sample(0)])
    with pytest.raises(OptionError, match="exists already"):
        LogWriter(path, RIG, EXPERIMENT, start_time_ns=0)
    partial_path(tmp_path / "y.mcap").write_bytes(b"")
    with pytest.raises(OptionError, match="partial recording left by a killed run"):
        LogWriter(tmp_path / "y.mcap", RIG, EXPERIMENT, start_time_ns=0)


def test_writer_flush_interval_bounded_by_the_crash_guarantee(tmp_path):
    with pytest.raises(OptionError, match=r"flush_interval_s must be in \(0, 0.25\]"):
        LogWriter(tmp_path / "z.mcap", RIG, EXPERIMENT, start_time_ns=0, flush_interval_s=1.0)


def test_metadata_round_trip():
    values = {"a": 1, "b": 0.001, "c": True, "d": ["u1", "u2"], "e": "text", "format_version":
              "1.0"}  # fmt: skip
    encoded = fmt.encode_metadata(values)
    assert all(isinstance(v, str) for v in encoded.values())
    decoded = fmt.decode_metadata(encoded)
    assert decoded == {"a": 1, "b": 0.001, "c": True, "d": "u1,u2", "e": "text",
                       "format_version": "1.0"}  # fmt: skip


def test_inspect_reports_a_salvaged_file(hframe_file, tmp_path, capsys):
    from hframe_id.cli import main

    cut = tmp_path / "cut.mcap.partial"
    cut.write_bytes(hframe_file.read_bytes()[: chunk_ends(hframe_file)[1]])
    assert main(["inspect", str(cut)]) == 0
    printed = capsys.readouterr().out
    assert "warning:" in printed and "recovered 200 samples" in printed
    assert "UNFINISHED, salvaged" in printed
    assert main(["inspect", str(tmp_path / "none.mcap")]) == 2
    assert "no such file" in capsys.readouterr().err
