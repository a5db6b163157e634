"""Import a CSV or MATLAB log of any rig into the log format (``SignalSample``, format 1.1).

``ImportSpec`` (``hframe_id.recordings.import_spec``) says which column is which channel
(time, input, output or extra signal, with its unit), the sample time, the sensors' noise
levels and the metadata. ``import_recording`` reads the file (``recordings.sources``), checks
the data (lengths, missing values, monotonic time), converts every column to SI at this edge
(``recordings.units``), writes the recording through a temporary file in the target's folder
and renames it only once it has been read back. A failed import leaves no file behind.
docs/import.md describes the command built on it, ``hframe-id import``.
"""

from __future__ import annotations

import datetime as dt
import os
import shutil
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hframe_id import __version__
from hframe_id.errors import LogFormatError, OptionError, renamed
from hframe_id.recordings import log_format as fmt
from hframe_id.recordings.channels import VALID_SUFFIX, Channels
from hframe_id.recordings.import_spec import RIG_KEYS, ColumnMap, ImportSpec
from hframe_id.recordings.reader import clock_mismatch, read_recording
from hframe_id.recordings.sources import SourceDataError, SourceTable, read_source
from hframe_id.recordings.units import COUNTS
from hframe_id.recordings.writer import LogWriter

#: ``rig.backend`` of imported recordings.
BACKEND = "import"
#: Sample time per chunk of an imported file [s] (large chunks compress well).
CHUNK_DURATION_S = 1.0


@dataclass(frozen=True)
class ImportResult:
    """What ``import_recording`` wrote: the file, its samples and channels, and which .mat
    scalars went into the rig metadata."""

    path: Path
    n_samples: int
    sample_period_s: float
    duration_s: float
    channels: Channels
    scalars: tuple[str, ...]


def import_recording(
    source: str | os.PathLike, out: str | os.PathLike, spec: ImportSpec, overwrite: bool = False
) -> ImportResult:
    """Convert ``source`` (CSV or .mat) into the recording ``out`` as ``spec`` says.

    Raises ``SourceDataError`` (the file's data) or ``OptionError`` (the spec, an existing
    ``out``), naming the file, the column and the value; nothing is written then.
    """
    out = Path(out)
    if out.exists() and not overwrite:
        raise OptionError(f"{out}: exists already; pass --force to replace it")
    channels = spec.channels()
    noise = spec.noise_std_si()
    table = read_source(source)
    time_s, data = _columns(table, spec)
    device_time_us, sample_period_s = _clock(table, spec, time_s, len(data[channels.inputs[0]]))
    rig = _rig_metadata(table, spec, channels, noise, sample_period_s)
    experiment = _experiment_metadata(table, spec)
    messages = _messages(channels, data, device_time_us)
    _write(out, rig, experiment, channels, messages, device_time_us, spec.start_time)
    return ImportResult(
        path=out,
        n_samples=len(device_time_us),
        sample_period_s=sample_period_s,
        duration_s=(device_time_us[-1] - device_time_us[0]) / 1e6,
        channels=channels,
        scalars=tuple(table.scalars),
    )


def _columns(
    table: SourceTable, spec: ImportSpec
) -> tuple[np.ndarray | None, dict[str, np.ndarray]]:
    """The time column [s] (None if not mapped) and the channels in SI by name: equal
    lengths, no missing values except in outputs of ``spec.nan_invalid``."""
    columns = [(c, table.column(c.source)) for c in spec.columns]
    lengths = {c.source: len(v) for c, v in columns}
    if len(set(lengths.values())) > 1:
        listed = ", ".join(f"{name} {n}" for name, n in lengths.items())
        raise SourceDataError(f"{table.path}: columns differ in length (samples: {listed})")
    time_s, data = None, {}
    for column, values in columns:
        missing = ~np.isfinite(values)
        if missing.any() and not (column.role == "output" and column.name in spec.nan_invalid):
            hint = {
                "output": f"; give --nan-invalid {column.name} to mark them invalid",
                "input": "; an input must have a value at every sample",
            }.get(column.role, "")
            raise SourceDataError(
                f"{table.path}: column {column.source!r} ({column.role}) has no value (empty, "
                f"NaN or inf) {_runs(table, missing)}{hint}"
            )
        si = spec.unit(column).factor * values
        if column.role == "time":
            time_s = si
        else:
            data[column.name] = si
    return time_s, data


def _runs(table: SourceTable, missing: np.ndarray) -> str:
    """Where the runs of True in ``missing`` are: the first one, and how many in all."""
    edges = np.diff(np.concatenate(([0], missing.astype(np.int8), [0])))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    first = (
        f"at {table.at(starts[0])}"
        if starts[0] == ends[0]
        else f"from {table.at(starts[0])} to {table.at(ends[0])}"
    )
    more = f" and in {len(starts) - 1} more run(s)" if len(starts) > 1 else ""
    return f"{first}{more} ({int(missing.sum())} sample(s) in all)"


#: The largest time the log's device clock holds: int64 microseconds (about 292,000 years).
MAX_CLOCK_S = (2**63 - 1) / 1e6


def _check_clock_range(table: SourceTable, column: ColumnMap, time_s: np.ndarray) -> None:
    """Every time [s] of the time ``column`` fits the device clock (``MAX_CLOCK_S``): a larger
    one overflowed the cast to microseconds, with numpy's warning."""
    beyond = np.flatnonzero(np.abs(time_s) > MAX_CLOCK_S)
    if beyond.size:
        i = int(beyond[0])
        raise SourceDataError(
            f"{table.path}: time column {column.source!r}: {table.at(i)} is "
            f"{table.column(column.source)[i]:.9g} {column.unit}, beyond the log's clock "
            f"(int64 microseconds, {MAX_CLOCK_S:.3g} s)"
        )


def _clock(
    table: SourceTable, spec: ImportSpec, time_s: np.ndarray | None, n: int
) -> tuple[np.ndarray, float]:
    """Device clock of each of the ``n`` samples [us] and the nominal sample period [s]."""
    if time_s is None:
        period = float(spec.sample_period_s)
        return np.round(np.arange(n) * period * 1e6).astype(np.int64), period
    column = next(c for c in spec.columns if c.role == "time")
    _check_clock_range(table, column, time_s)
    device_time_us = np.round(time_s * 1e6).astype(np.int64)
    steps = np.diff(device_time_us)
    if (steps <= 0).any():
        i = int(np.argmax(steps <= 0)) + 1
        raw = table.column(column.source)
        raise SourceDataError(
            f"{table.path}: time column {column.source!r} must increase strictly (to the "
            f"microsecond), but {table.at(i)} is {raw[i]:.9g} {column.unit} after "
            f"{raw[i - 1]:.9g} {column.unit}"
        )
    if spec.sample_period_s is not None:
        step_s = clock_mismatch(spec.sample_period_s, device_time_us, np.arange(n))
        if step_s is not None:
            raise OptionError(
                f"{table.path}: --sample-period {spec.sample_period_s:g} s does not match "
                f"time column {column.source!r}, whose samples are {step_s * 1e3:g} ms apart"
            )
        return device_time_us, float(spec.sample_period_s)
    if not steps.size:
        raise SourceDataError(f"{table.path}: one sample only; give --sample-period SECONDS")
    return device_time_us, float(np.median(steps)) / 1e6


def _rig_metadata(
    table: SourceTable,
    spec: ImportSpec,
    channels: Channels,
    noise: Mapping[str, float | str],
    sample_period_s: float,
) -> dict[str, Any]:
    clash = sorted(set(table.scalars) & (RIG_KEYS | set(spec.rig)))
    clash += [k for k in table.scalars if k.startswith(fmt.NOISE_STD_PREFIX)]
    if clash:
        raise SourceDataError(
            f"{table.path}: scalar variable(s) {', '.join(clash)} would overwrite rig "
            "metadata of the same name"
        )
    rig: dict[str, Any] = {"variant": spec.variant, "backend": BACKEND}
    if spec.rig_name:
        rig["name"] = spec.rig_name
    rig["sample_period_s"] = sample_period_s
    rig.update(channels.metadata())
    if any(c.unit == COUNTS for c in spec.columns):
        rig["encoder_counts_per_rev"] = spec.counts_per_rev
    for output in channels.outputs:
        if output in noise:
            rig[fmt.NOISE_STD_PREFIX + output] = noise[output]
    rig.update(table.scalars)
    rig.update(spec.rig)
    return rig


def _experiment_metadata(table: SourceTable, spec: ImportSpec) -> dict[str, Any]:
    start = "" if spec.start_time is None else spec.start_time.isoformat()
    experiment: dict[str, Any] = {
        "format_version": fmt.SIGNAL_FORMAT_VERSION,
        "software_version": f"hframe-id {__version__}",
        "operator": spec.operator,
        "start_time": start,
        "protocol": spec.protocol,
    }
    if spec.description:
        experiment["description"] = spec.description
    if spec.citation:
        experiment["citation"] = spec.citation
    experiment["source.file"] = table.path.name
    experiment["source.format"] = table.format
    experiment["source.sha256"] = table.sha256()
    experiment["source.map"] = " ".join(str(c) for c in spec.columns)
    experiment.update(spec.experiment)
    return experiment


def _messages(
    channels: Channels, data: Mapping[str, np.ndarray], device_time_us: np.ndarray
) -> list[dict[str, Any]]:
    """One ``SignalSample`` message per sample, fields in the schema's order."""
    fields: list[tuple[str, list]] = [
        ("sequence", list(range(len(device_time_us)))),
        ("device_time_us", device_time_us.tolist()),
    ]
    fields += [(name, data[name].tolist()) for name in channels.inputs]
    for name in channels.outputs:
        fields.append((name, data[name].tolist()))
        if name in channels.validity:
            fields.append((name + VALID_SUFFIX, np.isfinite(data[name]).tolist()))
    fields += [(name, data[name].tolist()) for name in channels.signals]
    names = [name for name, _ in fields]
    return [dict(zip(names, row, strict=True)) for row in zip(*(v for _, v in fields), strict=True)]


def _write(
    out: Path,
    rig: Mapping[str, Any],
    experiment: Mapping[str, Any],
    channels: Channels,
    messages: list[dict[str, Any]],
    device_time_us: np.ndarray,
    start_time: dt.datetime | None,
) -> None:
    """Write through a hidden folder beside ``out``, read it back, then rename into place."""
    start_ns = (
        0
        if start_time is None
        else int(start_time.timestamp()) * 10**9 + start_time.microsecond * 1000
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent))
    try:
        writer = LogWriter(
            staging / out.name,
            rig,
            experiment,
            start_time_ns=start_ns,
            chunk_duration_s=CHUNK_DURATION_S,
            flush_interval_s=None,
            sample_schema=channels.schema(),
        )
        for time_us, message in zip(
            (device_time_us - device_time_us[0]).tolist(), messages, strict=True
        ):
            writer.sample(time_us, message)
        written = writer.finish()
        read_recording(written)
        os.replace(written, out)
    except LogFormatError as err:
        raise renamed(err, staging / out.name, out) from None
    except OSError as err:  # a full disk, found when the file is closed
        raise LogFormatError(f"{out}: cannot write ({err.strerror or err})") from None
    finally:
        shutil.rmtree(staging, ignore_errors=True)
