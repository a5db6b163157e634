"""Logging speed: MCAP messages written and read per second, the logger's per-sample overhead,
and whether the logger keeps up with 1 kHz on the paced ``sim`` rig and the emulated ``serial``
rig (zero lost samples is the requirement; timing is reported, not asserted).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench import heading, median_time
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.reader import read_log, read_recording
from hframe_id.recordings.writer import LogWriter
from hframe_id.resources import models_dir
from hframe_id.rig.logger import RunOptions, run_experiment
from hframe_id.rig.protocols import StepProtocol
from hframe_id.rig.sim import SimRig

MODELS = models_dir()
PLANT = MODELS / "hframe-8-table4.2.yaml"
N_MESSAGES = 20_000
REAL_TIME_S = 2.0


def _message(k: int) -> dict:
    """Sample ``k`` of a plausible record: the lasers' valid readings stay inside their
    +/-5 cm range (the reader refuses a valid reading beyond it), the x laser's ramp
    starting over every 4,000 samples."""
    return {
        "sequence": k, "device_time_us": 1000 * k, "u1_V": -4.0, "u2_V": 4.0,
        "applied1_V": -4.0, "applied2_V": 4.0, "encoder1_counts": -3 * k,
        "encoder2_counts": 3 * k, "phi1_rad": -5.87e-5 * k, "phi2_rad": 5.87e-5 * k,
        "laser_x_m": 1.234567e-5 * (k % 4000), "laser_x_valid": True, "laser_y_m": 3.3e-7 * k,
        "laser_y_valid": True, "limit_x_min": False, "limit_x_max": False,
        "limit_y_min": False, "limit_y_max": False, "command_sequence": k - 1,
        "watchdog": False,
    }  # fmt: skip


EXPERIMENT = {
    "format_version": "1.0", "protocol": "step", "start_time": "2025-01-01T00:00:00+00:00",
    "operator": "bench", "software_version": "hframe-id bench",
}  # fmt: skip


def _write(path: Path, messages: list[dict], rig: dict) -> None:
    path.unlink(missing_ok=True)
    writer = LogWriter(path, rig, EXPERIMENT, start_time_ns=0)
    for m in messages:
        writer.sample(m["device_time_us"], m)
    writer.finish()


def _rig_only(n: int) -> None:
    rig = SimRig(load_parameter_file(PLANT), seed=0, paced=False)
    rig.start()
    volts = [-4.0, 4.0]
    for _ in range(n):
        sample = rig.read()
        rig.set_voltages(sample.sequence, volts)


def _real_time(rig, folder: Path, name: str) -> None:
    protocol = StepProtocol((-2.0, 2.0), REAL_TIME_S / 2, REAL_TIME_S, 0.05)
    out = folder / f"{name}.mcap"
    summary = run_experiment(rig, protocol, RunOptions(out=out, overwrite=True))
    recording = read_recording(out)
    lost = sum(m for _, m in recording.sequence_gaps) + summary.planned_samples
    lost -= recording.n_samples
    print(
        f"| {name} | {summary.samples}/{summary.planned_samples} | {lost} | "
        f"{summary.late_commands} | {summary.host_period_jitter_us:.0f} | "
        f"{summary.host_period_max_us:.0f} | {summary.host_latency_mean_us:.0f} | "
        f"{summary.host_latency_max_us:.0f} | {summary.overhead_mean_us:.0f} |",
        flush=True,
    )


def run() -> None:
    """Print MCAP write/read throughput, the logger's overhead per sample and whether the
    logger keeps up with 1 kHz in real time."""
    heading("logging: MCAP write/read throughput")
    messages = [_message(k) for k in range(N_MESSAGES)]
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        path = folder / "bench.mcap"
        rig_meta = SimRig(load_parameter_file(PLANT)).info.metadata()
        write_s = median_time(lambda: _write(path, messages, rig_meta), repeats=3)
        read_raw_s = median_time(lambda: read_log(path), repeats=3)
        read_s = median_time(lambda: read_recording(path), repeats=3, warmup=0)
        print("| operation | messages/s | us/message |")
        print("| --- | --- | --- |")
        for label, seconds in (
            ("write (queue, JSON, zstd chunks, finish)", write_s),
            ("read MCAP records (salvaging reader)", read_raw_s),
            ("read_recording (decode + validate)", read_s),
        ):
            print(f"| {label} | {N_MESSAGES / seconds:,.0f} | {seconds / N_MESSAGES * 1e6:.1f} |")
        print(
            f"\n{N_MESSAGES} samples: {path.stat().st_size / N_MESSAGES:.0f} bytes/sample on disk"
        )

        heading("logging: logger overhead per sample (unpaced sim rig, 2000 samples)")
        n = 2000
        params = load_parameter_file(PLANT)
        base_s = median_time(lambda: _rig_only(n), repeats=3)

        def logged() -> None:
            rig = SimRig(params, seed=0, paced=False)
            out = folder / "overhead.mcap"
            run_experiment(
                rig, StepProtocol((-4.0, 4.0), 1.0, n * 1e-3, 0.0),
                RunOptions(out=out, overwrite=True, handle_signals=False),
            )  # fmt: skip

        logged_s = median_time(logged, repeats=3)
        print("| loop | us/sample | ratio |")
        print("| --- | --- | --- |")
        print(f"| rig only (read + set_voltages) | {base_s / n * 1e6:.1f} | 1.00 |")
        print(f"| logger (rig + safety + queue + writer) | {logged_s / n * 1e6:.1f} | "
              f"{logged_s / base_s:.2f} |")  # fmt: skip
        print(f"\nlogger overhead: {(logged_s - base_s) / n * 1e6:.1f} us per sample "
              f"(budget at 1 kHz: 1000 us)")  # fmt: skip

        heading(f"logging: keeping up with 1 kHz in real time ({REAL_TIME_S:g} s runs)")
        print("| rig | samples | lost | late cmds | jitter std [us] | period max [us] | "
              "latency mean [us] | latency max [us] | loop [us] |")  # fmt: skip
        print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
        _real_time(SimRig(params, seed=0, paced=True), folder, "sim (paced)")
        process = subprocess.Popen(
            [sys.executable, "-m", "hframe_id.rig.emulator", "--params", str(PLANT)],
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
        )  # fmt: skip
        try:
            port = process.stdout.readline().split()[1]
            from hframe_id.rig.serial_rig import SerialRig

            with SerialRig(port) as rig:
                time.sleep(0.2)
                _real_time(rig, folder, "serial (emulated device, pty)")
        finally:
            process.terminate()
            process.wait(timeout=10)
        print("\nlost = planned samples missing from the file (the requirement is 0); late "
              "commands = device ticks that ran on the previous sample's command.")  # fmt: skip
