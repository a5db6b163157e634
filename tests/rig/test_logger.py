"""The logger: protocols, safety rules, signals, and crash safety with a real SIGKILL."""

from __future__ import annotations

import json
import mmap
import os
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from hframe_id.cli import main
from hframe_id.errors import OptionError
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.reader import TruncatedRecordingWarning, read_log, read_recording
from hframe_id.recordings.writer import partial_path
from hframe_id.rig.logger import RunOptions, run_experiment
from hframe_id.rig.protocols import (
    PulseProtocol,
    SequenceProtocol,
    StepProtocol,
    load_sequence_csv,
)
from hframe_id.rig.sim import SimRig

MODELS = Path(__file__).resolve().parents[2] / "models"
HFRAME = MODELS / "hframe-8-table4.2.yaml"
ONE_AXIS = MODELS / "one-axis-table2.3.yaml"


def sim(params: Path = HFRAME, **options) -> SimRig:
    return SimRig(load_parameter_file(params), seed=1, paced=False, **options)


# -- protocols ---------------------------------------------------------------------------------


def test_step_table_edges_fall_on_whole_samples():
    table = StepProtocol((-4.0, 4.0), step_s=0.5, duration_s=0.8, pre_roll_s=0.05).table(1e-3)
    assert table.shape == (800, 2)
    assert (table[:50] == 0).all() and (table[50:550] == [-4.0, 4.0]).all()
    assert (table[550:] == 0).all()


def test_pulse_drives_one_motor():
    table = PulseProtocol(5.0, 0.25, 0.6, 0.05, motor=2, n_inputs=2).table(1e-3)
    assert (table[:, 0] == 0).all() and table[:, 1].sum() == pytest.approx(5.0 * 250)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: StepProtocol((1.0,), 0.5, 0.3), "must fit in the record duration"),
        (lambda: StepProtocol((float("nan"),), 0.1, 0.3), "finite voltage"),
        (lambda: StepProtocol((1.0,), -0.1, 0.3), "finite time >= 0"),
        (lambda: PulseProtocol(5.0, 0.1, 0.3, motor=2), "pulse motor must be in 1..1"),
        (lambda: SequenceProtocol((0.0, 0.0), ((1.0,), (2.0,))), "strictly increasing"),
        (lambda: StepProtocol((1.0,), 0.1005, 0.3).table(1e-3), "not a whole number"),
    ],
)
def test_protocol_options_are_validated(make, message):
    with pytest.raises(OptionError, match=message):
        make()


def test_csv_sequence(tmp_path):
    path = tmp_path / "seq.csv"
    path.write_text("time [s],u1 [V],u2 [V]\n0.0,0,0\n0.010,2.5,-2.5\n0.020,0,0\n")
    protocol = load_sequence_csv(path)
    table = protocol.table(1e-3)
    assert table.shape == (21, 2)
    assert (
        (table[10:20] == [2.5, -2.5]).all() and (table[:10] == 0).all() and (table[20] == 0).all()
    )
    (tmp_path / "bad.csv").write_text("t,u1\n0,1\n")
    with pytest.raises(OptionError, match="header must be"):
        load_sequence_csv(tmp_path / "bad.csv")


def test_protocol_must_match_the_rig(tmp_path):
    with pytest.raises(OptionError, match="drives 1 motor.*has 2"):
        run_experiment(sim(), StepProtocol((1.0,), 0.1, 0.2), RunOptions(out=tmp_path / "x.mcap"))


# -- safety ------------------------------------------------------------------------------------


def test_voltages_are_clamped_and_the_clamp_logged(tmp_path):
    summary = run_experiment(
        sim(ONE_AXIS), PulseProtocol(14.0, 0.02, 0.05, 0.01), RunOptions(out=tmp_path / "c.mcap")
    )
    assert not summary.aborted
    recording = read_recording(tmp_path / "c.mcap")
    assert recording.inputs.max() == 10.0
    kinds = [e["kind"] for e in recording.events]
    assert kinds == ["start", "clamp", "stop"]


# -- the command line --------------------------------------------------------------------------


def test_record_and_inspect_commands(tmp_path, capsys):
    out = tmp_path / "run.mcap"
    argv = [
        "record",
        "--rig",
        "sim",
        "--params",
        str(HFRAME),
        "--fast",
        "--protocol",
        "step",
        "--v1",
        "-4",
        "--v2",
        "4",
        "--step",
        "0.1",
        "--duration",
        "0.15",
        "--out",
        str(out),
    ]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "samples        150 of 150 planned" in printed and "aborted        no" in printed
    assert "lost samples   0" in printed and "jitter" in printed
    assert main(argv) == 2  # refuses to overwrite
    assert "exists already" in capsys.readouterr().err
    assert main(["inspect", str(out), "--plot", str(tmp_path / "p.png")]) == 0
    printed = capsys.readouterr().out
    assert "/rig/sample" in printed and "150 messages" in printed and "finished" in printed
    assert "lost samples   0 in 0 gap(s)" in printed
    assert (tmp_path / "p.png").stat().st_size > 10_000


def test_record_csv_protocol_attaches_the_sequence(tmp_path, capsys):
    csv = tmp_path / "seq.csv"
    csv.write_text("time [s],u1 [V]\n0,0\n0.005,3\n")
    out = tmp_path / "csv.mcap"
    argv = ["record", "--rig", "sim", "--params", str(ONE_AXIS), "--fast", "--protocol", "csv",
            "--csv", str(csv), "--duration", "0.02", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    log = read_log(out)
    assert log.attachments["protocol.csv"].data == csv.read_bytes()
    assert read_recording(out).experiment["protocol"] == "sequence"


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--v1", "1"], "give --v2 as well"),
        ([], "needs --v1"),
        (["--v1", "1", "--v2", "1", "--port", "/dev/null"], "--port is for --rig serial"),
    ],
)
def test_record_options_are_checked(tmp_path, capsys, extra, message):
    argv = ["record", "--rig", "sim", "--params", str(HFRAME), "--out", str(tmp_path / "o.mcap")]
    assert main(argv + extra) == 2
    assert message in capsys.readouterr().err


# -- signals and crash safety (real processes) -------------------------------------------------


def wait_for(predicate, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise TimeoutError("condition not reached")
        time.sleep(0.02)


@pytest.mark.integration
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_signal_sets_zero_volts_and_finishes_the_file(tmp_path, signum):
    out = tmp_path / "sig.mcap"
    process = subprocess.Popen(
        [sys.executable, "-m", "hframe_id", "record", "--rig", "sim", "--params", str(HFRAME),
         "--v1", "-4", "--v2", "4", "--step", "20", "--duration", "30", "--out", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    partial = partial_path(out)
    # Wait until samples are being written (the first chunk is flushed after 100 ms).
    wait_for(lambda: partial.exists() and partial.stat().st_size > 5000)
    process.send_signal(signum)
    stdout, stderr = process.communicate(timeout=30)
    assert process.returncode == 1, stderr
    assert out.exists() and not partial.exists()
    assert f"aborted        yes: {signum.name} received" in stdout
    recording = read_recording(out)  # a finished file: no truncation warning
    assert recording.aborted and not recording.truncated
    assert [e["kind"] for e in recording.events][-2:] == ["signal", "abort"]
    np.testing.assert_array_equal(recording.inputs[-1], [0.0, 0.0])
    assert recording.n_samples < 30_000


KILL_CHILD = """
import mmap, struct, sys
from pathlib import Path
from hframe_id.parameters import load_parameter_file
from hframe_id.rig.logger import RunOptions, run_experiment
from hframe_id.rig.protocols import StepProtocol
from hframe_id.rig.sim import SimRig

handle = open(sys.argv[2], "r+b")
counter = mmap.mmap(handle.fileno(), 8)

class Counting(SimRig):
    def read(self):
        sample = super().read()
        struct.pack_into("<q", counter, 0, sample.sequence)  # the latest sample taken
        return sample

rig = Counting(load_parameter_file(sys.argv[1]), seed=4)  # paced in real time
run_experiment(rig, StepProtocol((-2.0, -2.0), 20.0, 30.0), RunOptions(out=Path(sys.argv[3])))
"""


@pytest.mark.integration
def test_sigkill_loses_at_most_the_last_250_ms(tmp_path):
    counter_file = tmp_path / "counter"
    counter_file.write_bytes(struct.pack("<q", -1))
    out = tmp_path / "killed.mcap"
    process = subprocess.Popen(
        [sys.executable, "-c", KILL_CHILD, str(HFRAME), str(counter_file), str(out)],
        stderr=subprocess.PIPE,
    )
    with open(counter_file, "r+b") as handle:
        counter = mmap.mmap(handle.fileno(), 8)

        def taken() -> int:
            return struct.unpack_from("<q", counter, 0)[0]

        wait_for(lambda: taken() >= 1500)
        # Freeze the logger, read how far it got, then kill it: no sample is taken in between.
        os.kill(process.pid, signal.SIGSTOP)
        last_taken = taken()
        os.kill(process.pid, signal.SIGKILL)
        process.wait(timeout=10)
        counter.close()
    assert process.returncode == -signal.SIGKILL
    partial = partial_path(out)
    assert partial.exists() and not out.exists()
    with pytest.warns(TruncatedRecordingWarning, match="recovered") as caught:
        recording = read_recording(partial)
    print(f"last sample taken {last_taken}:", caught[0].message)
    recovered_last = recording.n_samples - 1  # no samples are lost on the sim rig
    assert recording.truncated and recording.sequence_gaps == ()
    # The bound: everything up to at most 250 ms (250 samples) before the kill.
    assert last_taken - recovered_last <= 250, (last_taken, recovered_last)
    assert json.loads(read_log(partial).messages["/rig/event"][0][1])["kind"] == "start"
