"""Run one experiment on a rig and log it: the safety rules, the sample loop, the summary.

Safety, always on:
- commanded voltages are clamped to the DAC range (a ``clamp`` event says so once);
- a closed limit switch or a link fault sets 0 V at once, logs the event and aborts the run;
- SIGINT (Ctrl-C), SIGTERM and SIGHUP (unless ignored) set 0 V, log a ``signal`` event and
  finish the file properly.

The loop only reads a sample, looks up the protocol's voltage, commands it and queues the
message; encoding and disk writes happen on the writer's thread (``LogWriter``).
"""

from __future__ import annotations

import datetime as dt
import getpass
import math
import signal
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from hframe_id import __version__
from hframe_id.errors import OptionError, RigFault, stopping_signals
from hframe_id.recordings import log_format as fmt
from hframe_id.recordings.writer import (
    DEFAULT_CHUNK_DURATION_S,
    DEFAULT_FLUSH_INTERVAL_S,
    Attachment,
    LogWriter,
)
from hframe_id.rig.interface import Rig, RigInfo, RigSample

#: Sample time between two ``/rig/status`` messages [s].
STATUS_INTERVAL_S = 0.1


class ExperimentProtocol(Protocol):
    """What ``run_experiment`` needs of a protocol (``hframe_id.rig.protocols``).

    Attributes
    ----------
    name : protocol name, recorded as the ``protocol`` experiment field.
    n_inputs : voltages per row, one per rig input.
    """

    name: str
    n_inputs: int

    def table(self, period_s: float) -> np.ndarray:
        """(N, n_u) voltages [V] at sample period ``period_s`` [s], row k applied after sample k."""

    def metadata(self) -> dict[str, Any]:
        """The ``protocol.*`` fields of the recording's experiment record."""


@dataclass(frozen=True)
class RunOptions:
    """How to log a run.

    Attributes
    ----------
    out : the recording to write (``.mcap``).
    operator : who ran it (default: the login name).
    overwrite : replace an existing recording.
    reproducible : for unpaced sim runs: chunks by sample time only, host timing left out of
        the status messages, so that the same seed and start time give the same bytes.
    start_time : Unix time of sample 0 for the metadata and ``log_time`` (default: now).
    chunk_duration_s, flush_interval_s : see ``LogWriter``.
    progress : called about every 0.1 s of wall time with (samples done, samples planned,
        lost samples).
    handle_signals : turn SIGINT and SIGTERM into a clean stop (main thread only).
    notes : free text stored in the experiment metadata.
    """

    out: Path
    operator: str | None = None
    overwrite: bool = False
    reproducible: bool = False
    start_time: dt.datetime | None = None
    chunk_duration_s: float = DEFAULT_CHUNK_DURATION_S
    flush_interval_s: float = DEFAULT_FLUSH_INTERVAL_S
    progress: Callable[[int, int, int], None] | None = None
    handle_signals: bool = True
    notes: str = ""
    extra_experiment: dict[str, Any] = field(default_factory=dict)


@dataclass
class RunSummary:
    """What happened in a run (printed by ``hframe-id record``)."""

    path: Path
    samples: int = 0
    planned_samples: int = 0
    lost_samples: int = 0
    gaps: int = 0
    late_commands: int = 0
    crc_errors: int = 0
    duration_s: float = 0.0
    wall_s: float = 0.0
    aborted: bool = False
    abort_reason: str = ""
    host_period_mean_us: float = math.nan
    host_period_jitter_us: float = math.nan
    host_period_max_us: float = math.nan
    host_latency_mean_us: float = math.nan
    host_latency_max_us: float = math.nan
    overhead_mean_us: float = math.nan
    events: list[tuple[str, str]] = field(default_factory=list)

    def lines(self) -> list[str]:
        """The summary as aligned text lines, as ``hframe-id record`` prints it."""

        def us(value: float) -> str:
            return "n/a" if not math.isfinite(value) else f"{value:.0f} us"

        out = [
            f"recording      {self.path}",
            f"samples        {self.samples} of {self.planned_samples} planned "
            f"({self.duration_s:.3f} s of device time in {self.wall_s:.3f} s)",
            f"lost samples   {self.lost_samples} in {self.gaps} gap(s); late commands "
            f"{self.late_commands}; CRC errors {self.crc_errors}",
            f"timing         host period mean {us(self.host_period_mean_us)}, jitter (std) "
            f"{us(self.host_period_jitter_us)}, max {us(self.host_period_max_us)}; "
            f"command latency mean {us(self.host_latency_mean_us)}, max "
            f"{us(self.host_latency_max_us)}",
            f"logger         {us(self.overhead_mean_us)} per sample",
            "aborted        " + (f"yes: {self.abort_reason}" if self.aborted else "no"),
        ]
        return out


class _Running:
    """Running mean, standard deviation and maximum (Welford), without storing samples."""

    def __init__(self) -> None:
        self.n, self.mean, self.m2, self.max = 0, 0.0, 0.0, -math.inf

    def add(self, value: float) -> None:
        """Take one value into the running statistics."""
        self.n += 1
        delta = value - self.mean
        self.mean += delta / self.n
        self.m2 += delta * (value - self.mean)
        self.max = max(self.max, value)

    @property
    def std(self) -> float:
        """Sample standard deviation of the values so far (NaN for fewer than two)."""
        return math.sqrt(self.m2 / (self.n - 1)) if self.n > 1 else math.nan

    def values(self, scale: float = 1.0) -> tuple[float, float, float]:
        """(mean, standard deviation, maximum) times ``scale``; NaNs if there are no values."""
        if self.n == 0:
            return math.nan, math.nan, math.nan
        return self.mean * scale, self.std * scale, self.max * scale


class _StopRequest:
    def __init__(self) -> None:
        self.reason: str | None = None
        self._previous: dict[int, Any] = {}

    def install(self) -> None:
        """Catch SIGINT, SIGTERM and SIGHUP (``stopping_signals``) as a stop request (only
        possible on the main thread)."""
        if threading.current_thread() is not threading.main_thread():
            return
        for signum in stopping_signals():
            self._previous[signum] = signal.signal(signum, self._handle)

    def _handle(self, signum: int, frame: object) -> None:
        self.reason = f"{signal.Signals(signum).name} received"

    def restore(self) -> None:
        """Put back the signal handlers ``install`` replaced."""
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
        self._previous.clear()


def experiment_metadata(
    protocol: ExperimentProtocol, options: RunOptions, start: dt.datetime
) -> dict[str, Any]:
    """The ``experiment`` metadata record (see docs/log-format.md)."""
    operator = options.operator
    if operator is None:
        try:
            operator = getpass.getuser()
        except (KeyError, OSError):
            operator = "unknown"
    return {
        "format_version": fmt.FORMAT_VERSION,
        "software_version": f"hframe-id {__version__}",
        "operator": operator,
        "start_time": start.isoformat(timespec="microseconds"),
        "notes": options.notes,
        **protocol.metadata(),
        **options.extra_experiment,
    }


def run_experiment(
    rig: Rig,
    protocol: ExperimentProtocol,
    options: RunOptions,
    attachments: Sequence[Attachment] = (),
) -> RunSummary:
    """Run ``protocol`` on ``rig`` (started here, stopped at the end) and write the recording.

    The rig is left stopped with 0 V whatever happens; the recording is finished (renamed to
    its final name) whatever happens, with an ``abort`` event if the run did not complete.
    """
    table = _voltage_table(rig.info, protocol)
    writer = _open_writer(rig, protocol, options, attachments)
    stop = _StopRequest()
    if options.handle_signals:
        stop.install()
    run = _Run(rig, options, writer, table, stop)
    try:
        rig.start()
        run.event("start", f"{protocol.name} protocol, {run.n_planned} samples planned")
        while run.step():
            pass
    except BaseException as err:
        run.fail(err)
        raise
    finally:
        run.close()
    return run.summary


def _voltage_table(info: RigInfo, protocol: ExperimentProtocol) -> np.ndarray:
    """The protocol's (N, n_u) voltages [V] at the rig's sample period, once the protocol is
    checked to drive as many motors as the rig has."""
    if protocol.n_inputs != len(info.inputs):
        raise OptionError(
            f"protocol {protocol.name} drives {protocol.n_inputs} motor(s); the "
            f"{info.variant} rig has {len(info.inputs)} ({', '.join(info.inputs)})"
        )
    return protocol.table(info.sample_period_s)


def _open_writer(
    rig: Rig,
    protocol: ExperimentProtocol,
    options: RunOptions,
    attachments: Sequence[Attachment],
) -> LogWriter:
    """The recording's writer, its metadata and attachments written, sample 0 at
    ``options.start_time`` (default: now; it must carry a time zone)."""
    start = options.start_time or dt.datetime.now(dt.UTC)
    if start.tzinfo is None:
        raise OptionError("start_time must carry a time zone")
    start_ns = int(start.timestamp()) * 10**9 + start.microsecond * 1000
    return LogWriter(
        options.out,
        rig.info.metadata(),
        experiment_metadata(protocol, options, start),
        [*rig.attachments(), *attachments],
        start_time_ns=start_ns,
        chunk_duration_s=options.chunk_duration_s,
        flush_interval_s=None if options.reproducible else options.flush_interval_s,
        overwrite=options.overwrite,
    )


class _Run:
    """One run from ``rig.start()`` to the finished recording: the sample loop's state (the
    device clock, the last sequence numbers, the host timing statistics) and the summary.

    ``time_us`` is the device time since the first sample [us]; every event and status
    message is stamped with it.
    """

    def __init__(
        self,
        rig: Rig,
        options: RunOptions,
        writer: LogWriter,
        table: np.ndarray,
        stop: _StopRequest,
    ) -> None:
        info = rig.info
        self.rig, self.info, self.options, self.writer, self.stop = rig, info, options, writer, stop
        self.period_us = info.period_us
        self.table = table
        self.n_planned = table.shape[0]
        self.sensors = info.sensors
        self.clamped_table = np.clip(table, self.sensors.dac_min_v, self.sensors.dac_max_v)
        self.summary = RunSummary(path=writer.path, planned_samples=self.n_planned)
        self.zero = np.zeros(len(info.inputs))
        self.periods, self.latencies, self.overhead = _Running(), _Running(), _Running()
        self.first_time: int | None = None
        self.last_sequence: int | None = None
        self.last_commanded: int | None = None
        self.last_received: float | None = None
        self.next_status_us = 0
        self.time_us = 0
        self.clamp_reported = False
        self.wall_start = time.perf_counter()
        self.next_progress = self.wall_start
        self.encoder_step = self.sensors.encoder_step_rad
        self.sample: RigSample | None = None

    def event(self, kind: str, reason: str, sample: RigSample | None = None) -> None:
        """Log an event at the current device time and keep it for the summary."""
        self.summary.events.append((kind, reason))
        self.writer.event(
            self.time_us,
            kind,
            reason,
            sample.sequence if sample else None,
            sample.device_time_us if sample else None,
        )

    def status(self, sample: RigSample | None) -> None:
        """Log a ``/rig/status`` message: counters so far and host timing [us] (left out of
        reproducible runs)."""
        mean_p, std_p, max_p = self.periods.values(1e6)
        mean_l, _, max_l = self.latencies.values(1e6)
        timing = not self.options.reproducible
        self.writer.status(
            self.time_us,
            {
                "sequence": sample.sequence if sample else (self.last_sequence or 0),
                "samples": self.summary.samples,
                "lost_samples": self.summary.lost_samples,
                "crc_errors": self.rig.stats.crc_errors,
                "late_commands": self.summary.late_commands,
                "watchdog": bool(sample.watchdog) if sample else False,
                "host_latency_mean_us": mean_l if timing else None,
                "host_latency_max_us": max_l if timing else None,
                "host_period_jitter_us": std_p if timing else None,
                "host_period_max_us": max_p if timing else None,
                "queue_depth": self.writer.queue_depth() if timing else None,
            },
        )

    def step(self) -> bool:
        """Read one sample, command its voltage (0 V once a stop is due) and log both;
        False when the run is over (completed, stopped, or the link lost)."""
        try:
            sample = self.rig.read()
        except RigFault as fault:
            self._link_fault(fault)
            return False
        self.sample = sample
        busy_from = time.perf_counter()
        k = self._sample_index(sample)
        self._count_losses(sample)
        reason, kind = self._stop_reason(sample)
        if k >= self.n_planned:  # the last planned samples were lost: the run is over
            self.rig.set_voltages(sample.sequence, self.zero)
            return False
        volts = self.zero if reason is not None else self._planned_volts(k, sample)
        self.rig.set_voltages(sample.sequence, volts)
        commanded_at = time.perf_counter()
        self._record(sample, volts, commanded_at)
        if reason is not None:
            self.summary.aborted, self.summary.abort_reason = True, reason
            self.event(kind, reason, sample)
            self.event("abort", reason, sample)
            return False
        if self.time_us >= self.next_status_us:
            self.status(sample)
            self.next_status_us += round(STATUS_INTERVAL_S * 1e6)
        self.overhead.add(time.perf_counter() - busy_from)
        if self.options.progress is not None and commanded_at >= self.next_progress:
            self.options.progress(k + 1, self.n_planned, self.summary.lost_samples)
            self.next_progress = commanded_at + 0.1
        return k < self.n_planned - 1

    def _sample_index(self, sample: RigSample) -> int:
        """Advance ``time_us`` to the sample's device time; the protocol row it is due at."""
        if self.first_time is None:
            self.first_time = sample.device_time_us
        self.time_us = sample.device_time_us - self.first_time
        return round(self.time_us / self.period_us)

    def _count_losses(self, sample: RigSample) -> None:
        """Count the samples lost before this one and a command the device did not apply in
        time."""
        if self.last_sequence is not None:
            missing = sample.sequence - self.last_sequence - 1
            if missing > 0:
                self.summary.lost_samples += missing
                self.summary.gaps += 1
        if self.last_commanded is not None and sample.command_sequence != self.last_commanded:
            self.summary.late_commands += 1

    def _stop_reason(self, sample: RigSample) -> tuple[str | None, str]:
        """(reason, event kind) of a stop due now: a closed limit switch, else a signal;
        (None, "") to go on."""
        reason, kind = None, ""
        if self.stop.reason is not None:
            reason, kind = self.stop.reason, "signal"
        closed = [name for name, on in sample.limits.items() if on]
        if closed:
            reason, kind = f"limit switch {', '.join(closed)} closed", "limit"
        return reason, kind

    def _planned_volts(self, k: int, sample: RigSample) -> np.ndarray:
        """Row ``k`` of the protocol clamped to the DAC range [V]; the first clamp is logged."""
        volts = self.clamped_table[k]
        if not self.clamp_reported and (volts != self.table[k]).any():
            self.clamp_reported = True
            self.event(
                "clamp",
                f"requested {self.table[k].tolist()} V clamped to the DAC range "
                f"[{self.sensors.dac_min_v}, {self.sensors.dac_max_v}] V",
                sample,
            )
        return volts

    def _record(self, sample: RigSample, volts: np.ndarray, commanded_at: float) -> None:
        """Take the sample's host latency and period [s] into the statistics and queue its
        message with the voltages commanded [V]."""
        self.latencies.add(commanded_at - sample.received_s)
        if self.last_received is not None:
            self.periods.add(sample.received_s - self.last_received)
        self.last_received = sample.received_s
        self.last_sequence, self.last_commanded = sample.sequence, sample.sequence
        self.writer.sample(self.time_us, _message(self.info, sample, volts, self.encoder_step))
        self.summary.samples += 1

    def _link_fault(self, fault: RigFault) -> None:
        """Set 0 V (if the link still takes it) and log the fault as the run's abort."""
        _safe_zero(self.rig, self.last_sequence, self.zero)
        self.summary.aborted, self.summary.abort_reason = True, f"link fault: {fault}"
        self.event("link_fault", str(fault))
        self.event("abort", self.summary.abort_reason)

    def fail(self, err: BaseException) -> None:
        """Set 0 V (if the link still takes it) and log ``err`` as the run's abort."""
        _safe_zero(self.rig, self.last_sequence, self.zero)
        self.summary.aborted = True
        self.summary.abort_reason = f"{type(err).__name__}: {err}"
        self.event("abort", self.summary.abort_reason, self.sample)

    def close(self) -> None:
        """Stop the rig, put back the signal handlers, log the stop and a last status, fill
        in the summary's timing [s, us] and finish the recording."""
        summary = self.summary
        try:
            self.rig.stop()
        except RigFault as fault:
            self.event("note", f"stopping the rig failed: {fault}")
        self.stop.restore()
        if not summary.aborted:
            self.event("stop", f"completed {summary.samples} samples", self.sample)
        self.status(self.sample)
        summary.wall_s = time.perf_counter() - self.wall_start
        summary.duration_s = self.time_us * 1e-6
        summary.crc_errors = self.rig.stats.crc_errors
        (summary.host_period_mean_us, summary.host_period_jitter_us, summary.host_period_max_us) = (
            self.periods.values(1e6)
        )
        summary.host_latency_mean_us, _, summary.host_latency_max_us = self.latencies.values(1e6)
        summary.overhead_mean_us = self.overhead.values(1e6)[0]
        self.writer.finish()
        if self.options.progress is not None:
            self.options.progress(summary.samples, self.n_planned, summary.lost_samples)


def _safe_zero(rig: Rig, sequence: int | None, zero: np.ndarray) -> None:
    try:
        rig.set_voltages(sequence if sequence is not None else 0, zero)
    except Exception:  # the link is gone; the device watchdog drops the outputs itself
        pass


def _message(
    info: Any, sample: RigSample, volts: np.ndarray, encoder_step: float
) -> dict[str, Any]:
    """The flat ``/rig/sample`` message (docs/log-format.md)."""
    message: dict[str, Any] = {
        "sequence": sample.sequence,
        "device_time_us": sample.device_time_us,
    }
    n_in = len(info.inputs)
    for m in (1, 2):
        message[f"u{m}_V"] = float(volts[m - 1]) if m <= n_in else None
    for m in (1, 2):
        message[f"applied{m}_V"] = sample.applied_v[m - 1] if m <= n_in else None
    encoders = info.encoders
    for m in (1, 2):
        name = f"phi{m}"
        if name in encoders:
            counts = sample.encoder_counts[encoders.index(name)]
            message[f"encoder{m}_counts"] = counts
            message[f"phi{m}_rad"] = counts * encoder_step
        else:
            message[f"encoder{m}_counts"] = None
            message[f"phi{m}_rad"] = None
    lasers = info.lasers
    for axis in ("x", "y"):
        if axis in lasers:
            j = lasers.index(axis)
            message[f"laser_{axis}_m"] = sample.laser_m[j]  # NaN -> null in the writer
            message[f"laser_{axis}_valid"] = sample.laser_valid[j]
        else:
            message[f"laser_{axis}_m"] = None
            message[f"laser_{axis}_valid"] = None
    for name in fmt.LIMIT_SWITCHES:
        message[f"limit_{name}"] = sample.limits.get(name)
    message["command_sequence"] = sample.command_sequence
    message["watchdog"] = sample.watchdog
    return message
