"""The rig interface: the same tests for the ``sim`` backend and the ``serial`` backend talking
to an emulated device on a pseudo-terminal (in lockstep, so results do not depend on load).
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from hframe_id.parameters import load_parameter_file
from hframe_id.recordings import log_format as fmt
from hframe_id.recordings.reader import read_recording
from hframe_id.recordings.simulated import simulate_recording
from hframe_id.rig.interface import Rig
from hframe_id.rig.logger import RunOptions, run_experiment
from hframe_id.rig.protocols import StepProtocol
from hframe_id.rig.serial_rig import SerialRig
from hframe_id.rig.sim import SimRig

MODELS = Path(__file__).resolve().parents[2] / "models"
HFRAME = MODELS / "hframe-8-table4.2.yaml"
SEED = 9


@contextmanager
def emulator(*options: str, params: Path = HFRAME, seed: int = SEED) -> Iterator[str]:
    """Start the emulated device; yield its pseudo-terminal path; stop it."""
    process = subprocess.Popen(
        [sys.executable, "-m", "hframe_id.rig.emulator", "--params", str(params),
         "--seed", str(seed), *options],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
    )  # fmt: skip
    try:
        line = process.stdout.readline()
        assert line.startswith("PORT "), line
        yield line.split()[1]
    finally:
        process.terminate()
        process.wait(timeout=10)


# The link is not the subject of these tests unless a test says so: a link timeout far above a
# loaded machine's scheduling pauses (the default 0.1 s has been exceeded by the first sample
# with the suite on both cores, and by a pause on a load average of 12).
PATIENT_LINK_TIMEOUT_S = 5.0


@contextmanager
def emulated_rig(
    *options: str, link_timeout_s: float = PATIENT_LINK_TIMEOUT_S, **rig_options
) -> Iterator[SerialRig]:
    """The host side of an emulated device started with ``options``; closed on exit."""
    with (
        emulator(*options) as port,
        SerialRig(port, link_timeout_s=link_timeout_s, **rig_options) as rig,
    ):
        yield rig


@contextmanager
def open_rig(backend: str, travel: dict | None = None) -> Iterator[Rig]:
    if backend == "sim":
        rig = SimRig(load_parameter_file(HFRAME), seed=SEED, paced=False, travel_m=travel)
        yield rig
        rig.close()
        return
    options = ["--lockstep"]
    for axis, (low, high) in (travel or {}).items():
        options += ["--travel", axis, str(low), str(high)]
    with emulated_rig(*options) as rig:
        yield rig


BACKENDS = ["sim", "serial"]


@pytest.mark.parametrize("backend", BACKENDS)
def test_describes_itself(backend):
    with open_rig(backend) as rig:
        info = rig.info
        assert info.variant == "hframe-8" and info.backend == backend
        assert info.inputs == ("u1", "u2") and info.outputs == ("phi1", "phi2", "x", "y")
        assert info.sample_period_s == 1e-3
        assert info.sensors.encoder_counts_per_rev == 321084
        assert info.limit_switches == ("x_min", "x_max", "y_min", "y_max")
        assert set(fmt.RIG_REQUIRED) <= set(info.metadata())


@pytest.mark.parametrize("backend", BACKENDS)
def test_samples_are_numbered_timestamped_and_follow_commands(backend):
    with open_rig(backend) as rig:
        rig.start()
        first = rig.read()
        assert first.sequence == 0 and first.device_time_us == 0
        assert first.command_sequence is None and first.applied_v == (0.0, 0.0)
        assert first.encoder_counts == (0, 0) or max(map(abs, first.encoder_counts)) <= 1
        sample = first
        for _ in range(150):
            rig.set_voltages(sample.sequence, [5.0, 5.0])
            sample = rig.read()
        assert sample.sequence == 150 and sample.device_time_us == 150_000
        assert sample.command_sequence == 149
        step = rig.info.sensors.dac_step_v
        assert all(abs(v - 5.0) <= step / 2 for v in sample.applied_v)
        # Positive voltages turn both motors positive (section 1.3) and move y negative.
        assert all(c > 1000 for c in sample.encoder_counts)
        assert sample.laser_valid == (True, True) and sample.laser_m[1] < 0
        assert not any(sample.limits.values()) and not sample.watchdog


@pytest.mark.parametrize("backend", BACKENDS)
def test_voltages_are_clamped_to_the_dac_range(backend):
    with open_rig(backend) as rig:
        rig.start()
        sample = rig.read()
        rig.set_voltages(sample.sequence, [15.0, -15.0])
        sample = rig.read()
        s = rig.info.sensors
        assert sample.applied_v == (s.dac_max_v - s.dac_step_v, s.dac_min_v)


@pytest.mark.parametrize("backend", BACKENDS)
def test_logged_run_equals_the_batch_simulation(backend, tmp_path):
    protocol = StepProtocol((-6.0, 4.0), 0.15, 0.25, 0.02)
    with open_rig(backend) as rig:
        summary = run_experiment(rig, protocol, RunOptions(out=tmp_path / "r.mcap"))
    assert summary.samples == 250 and summary.lost_samples == 0 and not summary.aborted
    recording = read_recording(tmp_path / "r.mcap")
    batch = simulate_recording(load_parameter_file(HFRAME), protocol.table(1e-3), seed=SEED)
    np.testing.assert_array_equal(recording.inputs, batch.inputs)
    np.testing.assert_array_equal(recording.outputs[:, :2], batch.outputs[:, :2])  # counts
    # The serial link carries laser readings in whole nanometres.
    np.testing.assert_allclose(recording.outputs[:, 2:], batch.outputs[:, 2:], rtol=0, atol=5e-10)
    np.testing.assert_array_equal(recording.valid, batch.valid)
    assert recording.rig["backend"] == backend


@pytest.mark.parametrize("backend", BACKENDS)
def test_limit_switch_stops_the_motors_and_aborts(backend, tmp_path):
    # Limit switches 2 mm from the start: a -6 V y-motion reaches y_max within ~0.1 s.
    travel = {"x": (-0.25, 0.25), "y": (-0.25, 0.002)}
    with open_rig(backend, travel) as rig:
        summary = run_experiment(
            rig, StepProtocol((-6.0, -6.0), 0.5, 1.0, 0.0), RunOptions(out=tmp_path / "l.mcap")
        )
    assert summary.aborted and "limit switch y_max closed" in summary.abort_reason
    recording = read_recording(tmp_path / "l.mcap")
    assert recording.aborted and recording.n_samples < 1000
    kinds = [e["kind"] for e in recording.events]
    assert kinds == ["start", "limit", "abort"]
    np.testing.assert_array_equal(recording.inputs[-1], [0.0, 0.0])
    np.testing.assert_array_equal(recording.inputs[-2], [-6.0, -6.0])
