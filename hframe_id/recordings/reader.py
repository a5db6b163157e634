"""Read and validate recordings of the log format (docs/log-format.md).

``read_log`` walks the MCAP file record by record (it does not trust the summary at the end,
which a killed writer never wrote) and keeps everything up to the last complete, CRC-valid
chunk. ``read_recording`` checks that the content is an hframe-id recording (schemas, format
version, metadata, every sample field, monotonic time, sequence numbers, finite values) and
returns a ``Recording``; the sample messages of either schema are decoded by
``hframe_id.recordings.samples``.

Problems that make a file unusable raise ``LogFormatError`` naming the file and what is wrong.
Problems that leave usable data are warnings: ``TruncatedRecordingWarning`` (the writer was
killed; says how much was recovered) and ``SequenceGapWarning`` (samples lost on the link).
"""

from __future__ import annotations

import math
import os
import struct
import tempfile
import warnings
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from io import BytesIO
from pathlib import Path
from typing import Any

import numpy as np
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Attachment, Channel, Chunk, Header, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk

from hframe_id.documents import load_json, open_input
from hframe_id.errors import HframeIdError, LogFormatError, shown
from hframe_id.parameters import ParameterSet, load_parameter_file
from hframe_id.recordings import log_format as fmt
from hframe_id.recordings.channels import Channels
from hframe_id.recordings.recording import Recording
from hframe_id.recordings.samples import SampleColumns, decode_rig_samples, decode_signal_samples

MCAP_MAGIC = b"\x89MCAP0\r\n"
_RECORD_HEAD = struct.Struct("<BQ")
#: No MCAP record has opcode 0 (the spec's start at 0x01): where one is found the rest is
#: not records, typically zeros (a preallocated or sparse file), which were walked 9 bytes a
#: record, 19 s for 30 MB of zeros after the magic.
_NO_OPCODE = 0x00


class TruncatedRecordingWarning(UserWarning):
    """The file ends early (writer killed); the complete chunks were recovered."""


class SequenceGapWarning(UserWarning):
    """Sample sequence numbers skip: samples were lost between the device and the logger."""


@dataclass
class LogContents:
    """The raw content of an MCAP file, as far as it could be read.

    Attributes
    ----------
    complete : the file was finished (data end record, footer and closing magic present).
    problem : why reading stopped early (None if complete).
    chunks : complete chunks read.
    bytes_read, bytes_total : how far into the file the recovered records reach.
    messages : per topic, a list of (log_time [ns], payload bytes).
    """

    path: Path
    library: str = ""
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: dict[str, Attachment] = field(default_factory=dict)
    messages: dict[str, list[tuple[int, bytes]]] = field(default_factory=dict)
    complete: bool = False
    problem: str | None = None
    chunks: int = 0
    bytes_read: int = 0
    bytes_total: int = 0

    def channel(self, topic: str) -> Channel | None:
        """The channel that carries ``topic``, or None if the file has none."""
        for channel in self.channels.values():
            if channel.topic == topic:
                return channel
        return None

    def decoded(self, topic: str) -> list[dict[str, Any]]:
        """JSON messages of a topic, decoded."""
        return [
            load_json(data, f"{self.path}: {topic} message {i}", LogFormatError)
            for i, (_, data) in enumerate(self.messages.get(topic, []))
        ]


def read_log(path: str | os.PathLike) -> LogContents:
    """Read every record up to the end of the file or of its last complete chunk."""
    path = Path(path)
    try:
        with open_input(path) as stream:
            data = stream.read()
    except FileNotFoundError:
        raise LogFormatError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise LogFormatError(f"{path}: is a directory, not a recording") from None
    except OSError as err:
        raise LogFormatError(f"{path}: cannot read ({err.strerror})") from None
    if not data:
        raise LogFormatError(f"{path}: empty file (0 bytes), not a recording")
    if not data.startswith(MCAP_MAGIC):
        raise LogFormatError(f"{path}: not an MCAP file (no MCAP magic bytes at the start)")
    log = LogContents(path=path, bytes_total=len(data))
    position = len(MCAP_MAGIC)
    log.bytes_read = position
    while True:
        if position == len(data):
            log.problem = "file ends without a data-end record and footer"
            break
        if position + _RECORD_HEAD.size > len(data):
            log.problem = f"file ends inside a record header at byte {position}"
            break
        opcode, length = _RECORD_HEAD.unpack_from(data, position)
        if opcode == _NO_OPCODE:
            log.problem = f"corrupt record at byte {position} (opcode 0x00: zero-filled?)"
            break
        start = position + _RECORD_HEAD.size
        end = start + length
        if end > len(data):
            name = Opcode(opcode).name.lower() if opcode in Opcode._value2member_map_ else opcode
            log.problem = (
                f"file ends inside a {name} record at byte {position} "
                f"({len(data) - start} of its {length} bytes present)"
            )
            break
        body = data[start:end]
        try:
            if opcode == Opcode.DATA_END:
                log.complete = data.endswith(MCAP_MAGIC) and len(data) >= end + len(MCAP_MAGIC)
                if not log.complete:
                    log.problem = "file ends inside the summary section"
                log.bytes_read = end
                break
            _read_record(log, opcode, body)
        except Exception as err:  # any corrupt record: keep what came before it
            log.problem = f"corrupt record at byte {position} ({type(err).__name__}: {err})"
            break
        position = end
        log.bytes_read = end
    return log


def _read_record(log: LogContents, opcode: int, body: bytes) -> None:
    stream = ReadDataStream(BytesIO(body))
    if opcode == Opcode.HEADER:
        log.library = Header.read(stream).library
    elif opcode == Opcode.CHUNK:
        chunk = Chunk.read(stream)
        records = breakup_chunk(chunk, validate_crc=True)  # raises on a corrupt chunk
        staged = LogContents(path=log.path, schemas=dict(log.schemas), channels=dict(log.channels))
        for record in records:
            _add(staged, record)
        log.schemas.update(staged.schemas)
        log.channels.update(staged.channels)
        for topic, items in staged.messages.items():
            log.messages.setdefault(topic, []).extend(items)
        log.chunks += 1
    elif opcode == Opcode.ATTACHMENT:
        (crc,) = struct.unpack("<I", body[-4:])
        if crc and zlib.crc32(body[:-4]) != crc:
            raise ValueError("attachment CRC mismatch")
        _add(log, Attachment.read(stream))
    elif opcode == Opcode.METADATA:
        _add(log, Metadata.read(stream))
    elif opcode == Opcode.SCHEMA:
        _add(log, Schema.read(stream))
    elif opcode == Opcode.CHANNEL:
        _add(log, Channel.read(stream))
    elif opcode == Opcode.MESSAGE:
        _add(log, Message.read(stream, len(body)))


def _add(log: LogContents, record: Any) -> None:
    if isinstance(record, Schema):
        log.schemas[record.id] = record
    elif isinstance(record, Channel):
        log.channels[record.id] = record
    elif isinstance(record, Message):
        channel = log.channels.get(record.channel_id)
        if channel is None:
            raise ValueError(f"message on unknown channel {record.channel_id}")
        log.messages.setdefault(channel.topic, []).append((record.log_time, record.data))
    elif isinstance(record, Metadata):
        log.metadata[record.name] = dict(record.metadata)
    elif isinstance(record, Attachment):
        log.attachments[record.name] = record


# -- validation ------------------------------------------------------------------------------

#: Sample schema name -> the rig metadata keys its recordings must have.
_SAMPLE_SCHEMAS = {
    fmt.SAMPLE_SCHEMA_NAME: fmt.RIG_REQUIRED,
    fmt.SIGNAL_SAMPLE_SCHEMA_NAME: fmt.SIGNAL_RIG_REQUIRED,
}


#: How far the device clock's median step per sample may be from rig.sample_period_s.
CLOCK_TOLERANCE = 0.1


def clock_mismatch(period_s: float, device_time_us, sequence) -> float | None:
    """The device clock's median step per sample [s] if it contradicts the declared sample
    period ``period_s`` by more than CLOCK_TOLERANCE (e.g. 10 ms declared, samples 1 ms
    apart: replayed or fitted at that period, every time would be wrong); else None."""
    if len(sequence) < 2:
        return None
    step_s = float(np.median(np.diff(device_time_us) / np.diff(sequence))) * 1e-6
    return step_s if abs(step_s / period_s - 1) > CLOCK_TOLERANCE else None


def read_recording(path: str | os.PathLike) -> Recording:
    """Read, validate and return a recording (either sample schema).

    Raises
    ------
    LogFormatError
        Not an MCAP file, empty, not an hframe-id recording (other schema), unknown major
        format version, missing metadata or sample fields, a variant name that is not an
        identifier, an inconsistent channel declaration or noise level, non-monotonic time or
        sequence, non-finite values, nothing recoverable.

    Warns
    -----
    TruncatedRecordingWarning
        The file was not finished (writer killed); says how much was recovered.
    SequenceGapWarning
        Samples are missing (their count and position are in ``Recording.sequence_gaps``).
    """
    log = read_log(path)
    where = str(log.path)
    schema_name = _sample_schema_name(log, where)
    experiment = _experiment_metadata(log, where)
    rig, variant, sample_period_s = _rig_metadata(log, where, schema_name)
    decode = _sample_decoder(where, rig, schema_name)
    messages = log.decoded(fmt.SAMPLE_TOPIC)
    if not messages:
        raise LogFormatError(f"{where}: no samples on {fmt.SAMPLE_TOPIC}")
    samples = decode(where, messages)
    _check_noise_std(where, rig, samples.output_names)
    gaps = _sequence_gaps(samples.sequence)

    events = tuple(log.decoded(fmt.EVENT_TOPIC))
    aborted = any(e.get("kind") == "abort" for e in events)
    _check_clock(where, sample_period_s, samples)
    time_s = (samples.device_time_us - samples.device_time_us[0]) * 1e-6
    truth = _truth(log)
    if not log.complete:
        _warn_truncated(log, where, len(messages), time_s)
    if gaps:
        _warn_gaps(where, gaps, samples.sequence)
    return Recording(
        variant=variant,
        sample_period_s=float(sample_period_s),
        time_s=time_s,
        inputs=samples.inputs,
        input_names=samples.input_names,
        outputs=samples.outputs,
        output_names=samples.output_names,
        valid=samples.valid,
        units=dict(
            zip(
                samples.input_names + samples.output_names + samples.signal_names,
                samples.input_units + samples.output_units + samples.signal_units,
                strict=True,
            )
        ),
        signals=samples.signals,
        signal_names=samples.signal_names,
        rig=rig,
        experiment=experiment,
        truth=truth,
        sequence_gaps=gaps,
        aborted=aborted,
        path=log.path,
        truncated=not log.complete,
        events=events,
    )


def _sample_schema_name(log: LogContents, where: str) -> str:
    """The name of the sample channel's schema, one of ``_SAMPLE_SCHEMAS`` (jsonschema, with
    JSON messages); a file without that channel or schema is not an hframe-id recording."""
    channel = log.channel(fmt.SAMPLE_TOPIC)
    if channel is None:
        if not log.complete and not log.channels:
            raise LogFormatError(
                f"{where}: unfinished file with no complete chunk, nothing to recover "
                f"({log.problem})"
            )
        topics = ", ".join(sorted(c.topic for c in log.channels.values())) or "none"
        raise LogFormatError(
            f"{where}: no {fmt.SAMPLE_TOPIC} channel, not an hframe-id recording "
            f"(channels: {topics})"
        )
    schema = log.schemas.get(channel.schema_id)
    if (
        schema is None
        or schema.name not in _SAMPLE_SCHEMAS
        or schema.encoding != "jsonschema"
        or channel.message_encoding != "json"
    ):
        found = f"{shown(schema.name)} ({schema.encoding})" if schema else "no schema"
        expected = " or ".join(repr(name) for name in _SAMPLE_SCHEMAS)
        raise LogFormatError(
            f"{where}: {fmt.SAMPLE_TOPIC} has schema {found} with {shown(channel.message_encoding)}"
            f" messages; expected {expected} (jsonschema) with 'json' messages"
        )
    return schema.name


def _experiment_metadata(log: LogContents, where: str) -> dict[str, Any]:
    """The ``experiment`` metadata record, of a log format version this reader reads."""
    experiment = _metadata(log, "experiment", fmt.EXPERIMENT_REQUIRED)
    version = experiment["format_version"]
    if fmt.major_version(version) != fmt.SUPPORTED_MAJOR:
        raise LogFormatError(
            f"{where}: unknown log format version {shown(version)}; this hframe-id reads "
            f"{fmt.SUPPORTED_MAJOR}.x"
        )
    return experiment


def _rig_metadata(
    log: LogContents, where: str, schema_name: str
) -> tuple[dict[str, Any], str, int | float]:
    """The ``rig`` metadata record with the keys ``schema_name`` requires, its model variant
    (an identifier) and its sample period [s] (> 0)."""
    rig = _metadata(log, "rig", _SAMPLE_SCHEMAS[schema_name])
    variant = str(rig["variant"])
    if not fmt.VARIANT_PATTERN.match(variant):
        raise LogFormatError(
            f"{where}: rig.variant {shown(variant)} is not a model variant name (letters, digits, "
            "'-', '_')"
        )
    _check_rig_numbers(where, rig)
    return rig, variant, rig["sample_period_s"]


def _check_rig_numbers(where: str, rig: dict[str, Any]) -> None:
    """The numeric ``rig`` keys present are finite numbers in their ranges
    (``fmt.RIG_NUMBERS``, ``fmt.RIG_RANGES``)."""
    for key, (lowest, allowed, highest) in fmt.RIG_NUMBERS.items():
        if key not in rig:
            continue
        value = rig[key]
        number = isinstance(value, int | float) and not isinstance(value, bool)
        if not (
            number
            and math.isfinite(value)
            and (value >= lowest if allowed else value > lowest)
            and value <= highest
        ):
            bound = f"{'>=' if allowed else '>'} {lowest:g}"
            bound += f" and <= {highest:g}" if math.isfinite(highest) else ""
            raise LogFormatError(f"{where}: rig.{key} must be a number {bound}, got {shown(value)}")
    for low, high in fmt.RIG_RANGES:
        if low in rig and high in rig and not _numbers_ordered(rig[low], rig[high]):
            raise LogFormatError(
                f"{where}: rig.{low} {shown(rig[low])} must be a number below rig.{high} "
                f"{shown(rig[high])}"
            )


def _numbers_ordered(low: Any, high: Any) -> bool:
    numbers = all(isinstance(v, int | float) and not isinstance(v, bool) for v in (low, high))
    return numbers and math.isfinite(low) and math.isfinite(high) and low < high


def _sample_decoder(
    where: str, rig: dict[str, Any], schema_name: str
) -> Callable[[str, list[dict[str, Any]]], SampleColumns]:
    """The decoder of ``schema_name``'s sample messages, given the rig metadata (the signal
    schema's channels are declared there)."""
    if schema_name == fmt.SAMPLE_SCHEMA_NAME:
        return partial(decode_rig_samples, rig=rig)
    try:
        channels = Channels.from_rig(rig)
    except ValueError as err:
        raise LogFormatError(f"{where}: rig metadata: {err}") from None
    return partial(decode_signal_samples, channels=channels)


def _sequence_gaps(sequence: np.ndarray) -> tuple[tuple[int, int], ...]:
    """(index of the first sample after the gap, samples lost) per gap in ``sequence``."""
    steps = np.diff(sequence)
    gap_at = np.flatnonzero(steps > 1)
    return tuple((int(i + 1), int(steps[i] - 1)) for i in gap_at)


def _check_clock(where: str, sample_period_s: int | float, samples: SampleColumns) -> None:
    """The device clock agrees with rig.sample_period_s [s] (``clock_mismatch``)."""
    step_s = clock_mismatch(float(sample_period_s), samples.device_time_us, samples.sequence)
    if step_s is not None:
        raise LogFormatError(
            f"{where}: rig.sample_period_s {sample_period_s:g} s does not match the device "
            f"clock, whose samples are {step_s * 1e3:g} ms apart (device_time_us)"
        )


def _warn_truncated(log: LogContents, where: str, n_samples: int, time_s: np.ndarray) -> None:
    """Warn that the file is unfinished, with how much was recovered (``time_s`` [s]); the
    warning points at ``read_recording``'s caller."""
    recovered = f"{n_samples} samples ({time_s[-1]:.3f} s)" if len(time_s) else "nothing"
    warnings.warn(
        f"{where}: file is unfinished (writer killed?): {log.problem}; recovered "
        f"{recovered} from {log.chunks} complete chunk(s), {log.bytes_read} of "
        f"{log.bytes_total} bytes",
        TruncatedRecordingWarning,
        stacklevel=3,
    )


def _warn_gaps(where: str, gaps: tuple[tuple[int, int], ...], sequence: np.ndarray) -> None:
    """Warn of samples lost on the link (``_sequence_gaps``); the warning points at
    ``read_recording``'s caller."""
    lost = sum(n for _, n in gaps)
    warnings.warn(
        f"{where}: {lost} sample(s) lost in {len(gaps)} gap(s) of the sequence numbers "
        f"(first before sample {gaps[0][0]}, sequence {sequence[gaps[0][0]]})",
        SequenceGapWarning,
        stacklevel=3,
    )


def _metadata(log: LogContents, name: str, required: tuple[str, ...]) -> dict[str, Any]:
    if name not in log.metadata:
        raise LogFormatError(f"{log.path}: no {name!r} metadata record")
    raw = log.metadata[name]
    missing = [key for key in required if key not in raw]
    if missing:
        raise LogFormatError(f"{log.path}: {name} metadata lacks {', '.join(missing)}")
    return fmt.decode_metadata(raw)


def _check_noise_std(where: str, rig: dict[str, Any], outputs: tuple[str, ...]) -> None:
    """Every ``noise_std_<output>`` key names an output and holds a float > 0 or 'estimate'."""
    for key, value in rig.items():
        if not key.startswith(fmt.NOISE_STD_PREFIX):
            continue
        output = key.removeprefix(fmt.NOISE_STD_PREFIX)
        if output not in outputs:
            raise LogFormatError(
                f"{where}: rig.{key} names no output (outputs: {', '.join(outputs)})"
            )
        try:
            fmt.parse_noise_std(value)
        except ValueError as err:
            raise LogFormatError(f"{where}: rig.{key} {err}") from None


def _truth(log: LogContents) -> ParameterSet | None:
    attachment = log.attachments.get(fmt.PLANT_ATTACHMENT)
    if attachment is None:
        return None
    with tempfile.TemporaryDirectory() as folder:
        file = Path(folder) / fmt.PLANT_ATTACHMENT
        file.write_bytes(attachment.data)
        try:
            params = load_parameter_file(file)
        except HframeIdError as err:
            message = str(err).replace(str(file), f"{log.path}[{fmt.PLANT_ATTACHMENT}]")
            raise LogFormatError(f"attached plant parameters are invalid: {message}") from None
    params.path = Path(f"{log.path}[{fmt.PLANT_ATTACHMENT}]")
    return params
