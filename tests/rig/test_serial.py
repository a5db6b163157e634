"""The serial protocol: framing, and the host against an emulated device with injected faults."""

from __future__ import annotations

import numpy as np
import pytest
from test_rig_backends import PATIENT_LINK_TIMEOUT_S, emulated_rig, emulator

from hframe_id.errors import RigFault
from hframe_id.recordings.reader import SequenceGapWarning, read_recording
from hframe_id.rig import serial_protocol as sp
from hframe_id.rig.logger import RunOptions, run_experiment
from hframe_id.rig.protocols import StepProtocol
from hframe_id.rig.serial_rig import SerialRig

STEP = StepProtocol((-4.0, 4.0), 0.2, 0.3, 0.02)


# -- framing -----------------------------------------------------------------------------------


def test_frames_round_trip_byte_by_byte():
    frames = [(sp.COMMAND, sp.COMMAND_PAYLOAD.pack(7, 100, 4000)), (sp.HELLO, b""),
              (sp.INFO, b'{"a":1}')]  # fmt: skip
    stream = b"".join(sp.encode(t, p) for t, p in frames)
    decoder = sp.Decoder()
    out = []
    for i in range(len(stream)):
        out += decoder.feed(stream[i : i + 1])
    assert out == frames and decoder.crc_errors == 0


def test_crc_is_ccitt_false():
    assert sp.crc16(b"123456789") == 0x29B1  # the check value of CRC-16/CCITT-FALSE


def test_corrupted_frame_is_dropped_and_the_next_one_found():
    good = sp.encode(sp.COMMAND, sp.COMMAND_PAYLOAD.pack(1, 2, 3))
    bad = bytearray(sp.encode(sp.COMMAND, sp.COMMAND_PAYLOAD.pack(4, 5, 6)))
    bad[7] ^= 0x01
    decoder = sp.Decoder()
    out = decoder.feed(b"\x00\xa5garbage" + bytes(bad) + good)
    assert out == [(sp.COMMAND, sp.COMMAND_PAYLOAD.pack(1, 2, 3))]
    assert decoder.crc_errors == 1 and decoder.bytes_discarded > 0


def test_impossible_length_resynchronizes():
    decoder = sp.Decoder()
    junk = sp.HEAD.pack(sp.SYNC, sp.SAMPLE, sp.MAX_PAYLOAD + 1)
    assert decoder.feed(junk + sp.encode(sp.STOP)) == [(sp.STOP, b"")]


def test_payload_limit():
    with pytest.raises(ValueError, match="exceeds"):
        sp.encode(sp.INFO, bytes(sp.MAX_PAYLOAD + 1))


# -- faults, end to end ------------------------------------------------------------------------


def test_corrupted_frames_are_lost_samples_not_a_fault(tmp_path):
    with emulated_rig("--lockstep", "--corrupt-every", "50") as rig:
        summary = run_experiment(rig, STEP, RunOptions(out=tmp_path / "c.mcap"))
    # Sequences 49, 99, ..., 299 were corrupted; the last one ends the run (nothing follows).
    assert not summary.aborted and summary.crc_errors >= 6 and summary.lost_samples == 6
    with pytest.warns(SequenceGapWarning, match="5 sample.s. lost in 5 gap"):
        recording = read_recording(tmp_path / "c.mcap")
    assert recording.sequence_gaps[:2] == ((49, 1), (98, 1))
    assert recording.n_samples == 300 - 6


def test_dropped_frames_are_lost_samples(tmp_path):
    with emulated_rig("--lockstep", "--drop-every", "40") as rig:
        summary = run_experiment(rig, STEP, RunOptions(out=tmp_path / "d.mcap"))
    assert not summary.aborted and summary.lost_samples == 7 and summary.gaps == 7
    assert summary.crc_errors == 0
    with pytest.warns(SequenceGapWarning):
        recording = read_recording(tmp_path / "d.mcap")
    assert sum(n for _, n in recording.sequence_gaps) == 7


@pytest.mark.parametrize(
    ("fault", "timeout_s", "message"),
    [
        ("--stop-after", 0.5, "no sample for 500 ms"),
        ("--disconnect-after", 5.0, "serial link lost"),
    ],
)
def test_link_fault_aborts_the_run_and_finishes_the_file(tmp_path, fault, timeout_s, message):
    """Link timeouts far above a loaded machine's scheduling pauses (the default 0.1 s was
    once exceeded by a pause before the disconnect on a load average of 12), so that only the
    injected fault can end the run."""
    with emulated_rig("--lockstep", fault, "120", link_timeout_s=timeout_s) as rig:
        summary = run_experiment(rig, STEP, RunOptions(out=tmp_path / "f.mcap"))
    assert summary.aborted and message in summary.abort_reason
    recording = read_recording(tmp_path / "f.mcap")
    assert recording.aborted and not recording.truncated and recording.n_samples == 120
    assert [e["kind"] for e in recording.events] == ["start", "link_fault", "abort"]


def test_device_watchdog_drops_the_outputs_when_commands_stop():
    # Real time here: the watchdog runs on the device's own clock. The host may lag behind
    # the device on a loaded machine (samples wait in the OS buffer), so the checks look for
    # what must happen eventually rather than at a given sample.
    with emulated_rig(watchdog_ms=20) as rig:
        rig.start()
        sample = rig.read()
        rig.set_voltages(sample.sequence, [3.0, 3.0])
        seen = [rig.read() for _ in range(200)]  # no further commands
        assert any(abs(s.applied_v[0] - 3.0) < 0.01 and not s.watchdog for s in seen)
        assert seen[-1].watchdog and seen[-1].applied_v == (0.0, 0.0)
        resumed = sample = seen[-1]
        for _ in range(1000):  # commanding again, every sample, until the device has it
            rig.set_voltages(sample.sequence, [1.0, 1.0])
            sample = rig.read()
            if (sample.command_sequence or 0) > resumed.sequence:
                break
        assert not sample.watchdog and abs(sample.applied_v[0] - 1.0) < 0.01


def test_device_cuts_the_outputs_on_a_limit_switch_whatever_the_host_commands():
    # Limit switch 2 mm from the start: -6 V y-motion reaches y_max within ~0.1 s. The host
    # here keeps commanding -6 V (a host without the logger's own limit check).
    with emulated_rig("--lockstep", "--travel", "y", "-0.25", "0.002") as rig:
        rig.start()
        samples = [rig.read()]
        for _ in range(300):
            rig.set_voltages(samples[-1].sequence, [-6.0, -6.0])
            samples.append(rig.read())
    closed = [i for i, s in enumerate(samples) if any(s.limits.values())]
    assert closed, "the stage never reached the limit switch"
    first = closed[0]
    assert samples[first].limits["y_max"]
    assert samples[first].applied_v == pytest.approx((-6.0, -6.0), abs=0.01)
    # from the next interval on: 0 V, latched even if the stage comes off the switch
    assert all(s.applied_v == (0.0, 0.0) for s in samples[first + 1 :])
    assert samples[-1].command_sequence == samples[-2].sequence  # commands still arrive


def test_real_time_run_records_every_sample(tmp_path):
    with emulated_rig() as rig:
        summary = run_experiment(rig, STEP, RunOptions(out=tmp_path / "rt.mcap"))
    recording = read_recording(tmp_path / "rt.mcap")
    assert not summary.aborted
    # Lost samples would be warned about and counted; device time is the device's own clock.
    assert recording.n_samples + summary.lost_samples == 300
    assert np.all(np.diff(recording.time_s) > 0)


def test_no_device_on_the_port(tmp_path):
    with pytest.raises(RigFault, match="cannot open the serial port"):
        SerialRig(str(tmp_path / "ttyNOPE"))


def test_record_command_on_the_serial_rig(tmp_path, capsys):
    from hframe_id.cli import main

    out = tmp_path / "serial.mcap"
    with emulator("--lockstep") as port:
        argv = ["record", "--rig", "serial", "--port", port, "--v1", "-4", "--v2", "4",
                "--step", "0.1", "--duration", "0.15",
                "--link-timeout", str(PATIENT_LINK_TIMEOUT_S), "--out", str(out)]  # fmt: skip
        assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "samples        150 of 150 planned" in printed and "aborted        no" in printed
    recording = read_recording(out)
    assert recording.rig["backend"] == "serial" and recording.rig["serial_number"].startswith("EMU")
    assert recording.rig["device.plant_parameters"] == "hframe-8-table4.2.yaml"
