"""Crash-safe MCAP writer of the log format (docs/log-format.md).

Why a writer thread: JSON encoding, compression and disk writes must stay off the sampling
path, so ``sample()`` only puts the message on a queue. The thread closes a chunk (compressed,
CRC'd, written and flushed to the OS) every ``chunk_duration_s`` of sample time and at least
every ``flush_interval_s`` of wall time, so that a writer killed at any instant leaves a file
whose complete chunks hold all but the last fraction of a second (the reader salvages them).

The file is written as ``<name>.partial`` and renamed to ``<name>`` by ``finish()`` after an
fsync, so a finished name always holds a finished file.
"""

from __future__ import annotations

import json
import math
import os
import queue
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mcap.writer import CompressionType, Writer

from hframe_id import __version__
from hframe_id.errors import LogFormatError, OptionError
from hframe_id.recordings import log_format as fmt

#: Longest wall time between two chunk flushes [s]; the issue's bound is 250 ms.
DEFAULT_FLUSH_INTERVAL_S = 0.1
#: Sample time per chunk [s] (100 samples at 1 kHz).
DEFAULT_CHUNK_DURATION_S = 0.1

_STOP = object()


@dataclass(frozen=True)
class Attachment:
    """A file carried inside the recording (plant parameters, protocol CSV)."""

    name: str
    media_type: str
    data: bytes


def partial_path(path: str | os.PathLike) -> Path:
    """Where a recording is written until it is finished: ``<name>.partial``."""
    path = Path(path)
    return path.with_name(path.name + ".partial")


def _nan_to_null(message: Mapping[str, Any]) -> dict[str, Any]:
    return {
        k: (None if isinstance(v, float) and not math.isfinite(v) else v)
        for k, v in message.items()
    }


class LogWriter:
    """Write one recording: metadata and attachments at once, messages through a thread.

    Parameters
    ----------
    path : the finished file's name (``.mcap``).
    rig, experiment : the two metadata records (values of any scalar type or lists; they are
        written as strings, see ``log_format.encode_metadata``).
    attachments : files to carry (plant parameters of a sim rig, a protocol's CSV).
    start_time_ns : Unix time of sample time 0 [ns]; ``log_time`` = this + sample time.
    chunk_duration_s : sample time per chunk [s].
    flush_interval_s : longest wall time between flushes [s]; None for chunks by sample time
        only (byte-reproducible files from unpaced runs, e.g. the shipped datasets).
    overwrite : replace an existing file (and a leftover ``.partial``).
    compression : ``"zstd"``, ``"lz4"`` or ``"none"``.
    sample_schema : JSON Schema of the ``/rig/sample`` messages, registered under its
        ``title``: the H-frame rig's ``RigSample`` (default) or a recording's
        ``SignalSample`` schema (``Channels.schema()``).
    """

    def __init__(
        self,
        path: str | os.PathLike,
        rig: Mapping[str, Any],
        experiment: Mapping[str, Any],
        attachments: Sequence[Attachment] = (),
        *,
        start_time_ns: int,
        chunk_duration_s: float = DEFAULT_CHUNK_DURATION_S,
        flush_interval_s: float | None = DEFAULT_FLUSH_INTERVAL_S,
        overwrite: bool = False,
        compression: str = "zstd",
        sample_schema: Mapping[str, Any] = fmt.SAMPLE_SCHEMA,
    ) -> None:
        if not chunk_duration_s > 0:
            raise OptionError(f"chunk_duration_s must be > 0 s, got {chunk_duration_s}")
        if flush_interval_s is not None and not 0 < flush_interval_s <= 0.25:
            raise OptionError(
                f"flush_interval_s must be in (0, 0.25] s (crash safety), got {flush_interval_s}"
            )
        codecs = {
            "zstd": CompressionType.ZSTD,
            "lz4": CompressionType.LZ4,
            "none": CompressionType.NONE,
        }
        if compression not in codecs:
            raise OptionError(
                f"compression must be one of {', '.join(codecs)}, got {compression!r}"
            )
        self.path = Path(path)
        self.partial = partial_path(self.path)
        for existing, what in (
            (self.path, "exists already"),
            (self.partial, "is a partial recording left by a killed run"),
        ):
            if existing.exists() and not overwrite:
                raise OptionError(f"{existing}: {what}; move it away or pass --force")
        self.start_time_ns = int(start_time_ns)
        self._chunk_us = round(chunk_duration_s * 1e6)
        self._flush_interval_s = flush_interval_s
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            self._stream = open(self.partial, "wb")  # noqa: SIM115 (closed by finish)
        except OSError as err:
            raise LogFormatError(f"{self.partial}: cannot create ({err.strerror})") from None
        self._mcap = Writer(self._stream, chunk_size=1 << 30, compression=codecs[compression])
        self._mcap.start(profile="", library=f"hframe-id/{__version__}")
        channels = {}
        for topic, name, schema in (
            (fmt.SAMPLE_TOPIC, sample_schema["title"], sample_schema),
            (fmt.EVENT_TOPIC, fmt.EVENT_SCHEMA_NAME, fmt.EVENT_SCHEMA),
            (fmt.STATUS_TOPIC, fmt.STATUS_SCHEMA_NAME, fmt.STATUS_SCHEMA),
        ):
            schema_id = self._mcap.register_schema(name, "jsonschema", fmt.schema_bytes(schema))
            channels[topic] = self._mcap.register_channel(topic, "json", schema_id)
        self._channels = channels
        self._mcap.add_metadata("rig", fmt.encode_metadata(rig))
        self._mcap.add_metadata("experiment", fmt.encode_metadata(experiment))
        for item in attachments:
            self._mcap.add_attachment(
                create_time=self.start_time_ns,
                log_time=self.start_time_ns,
                name=item.name,
                media_type=item.media_type,
                data=item.data,
            )
        self._stream.flush()
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._error: BaseException | None = None
        self._finished = False
        self.messages_written = 0
        self.chunks_written = 0
        self._thread = threading.Thread(target=self._run, name="hframe-id log writer", daemon=True)
        self._thread.start()

    # -- the sampling side: cheap, never blocks on the disk ------------------------------------
    def sample(self, time_us: int, message: dict[str, Any]) -> None:
        """Queue one ``/rig/sample`` message at sample time ``time_us`` [us] since sample 0."""
        if self._error is not None:
            self._raise_error()
        self._queue.put((fmt.SAMPLE_TOPIC, time_us, message))

    def event(
        self,
        time_us: int,
        kind: str,
        reason: str,
        sequence: int | None = None,
        device_time_us: int | None = None,
    ) -> None:
        """Queue one ``/rig/event`` message."""
        if kind not in fmt.EVENT_KINDS:
            raise ValueError(f"event kind must be one of {fmt.EVENT_KINDS}, got {kind!r}")
        self._queue.put(
            (
                fmt.EVENT_TOPIC,
                time_us,
                {
                    "kind": kind,
                    "reason": reason,
                    "sequence": sequence,
                    "device_time_us": device_time_us,
                },
            )
        )

    def status(self, time_us: int, message: dict[str, Any]) -> None:
        """Queue one ``/rig/status`` message."""
        self._queue.put((fmt.STATUS_TOPIC, time_us, message))

    def queue_depth(self) -> int:
        """Messages queued and not yet written (reported in ``/rig/status``)."""
        return self._queue.qsize()

    # -- the writer thread ---------------------------------------------------------------------
    def _run(self) -> None:
        pending = 0
        chunk_start_us: int | None = None
        last_flush = time.monotonic()
        wait = 0.02 if self._flush_interval_s is None else min(0.02, self._flush_interval_s / 4)
        try:
            while True:
                try:
                    item = self._queue.get(timeout=wait)
                except queue.Empty:
                    item = None
                if item is _STOP:
                    break
                if item is not None:
                    topic, time_us, message = item
                    if topic == fmt.SAMPLE_TOPIC:
                        if chunk_start_us is None:
                            chunk_start_us = time_us
                        elif time_us - chunk_start_us >= self._chunk_us and pending:
                            self._flush()
                            pending, last_flush, chunk_start_us = 0, time.monotonic(), time_us
                    log_time = self.start_time_ns + int(time_us) * 1000
                    data = json.dumps(_nan_to_null(message), allow_nan=False).encode()
                    self._mcap.add_message(
                        self._channels[topic],
                        log_time=log_time,
                        data=data,
                        publish_time=log_time,
                        sequence=self.messages_written & 0xFFFFFFFF,
                    )
                    self.messages_written += 1
                    pending += 1
                if (
                    pending
                    and self._flush_interval_s is not None
                    and time.monotonic() - last_flush >= self._flush_interval_s
                ):
                    self._flush()
                    pending, last_flush, chunk_start_us = 0, time.monotonic(), None
        except BaseException as err:  # reported to the sampling side by sample() / finish()
            self._error = err

    def _flush(self) -> None:
        self._mcap.flush()
        self.chunks_written += 1

    def _raise_error(self) -> None:
        err = self._error
        if isinstance(err, OSError):
            raise LogFormatError(f"{self.partial}: writing failed ({err.strerror or err})") from err
        raise LogFormatError(f"{self.partial}: writing failed ({err!r})") from err

    # -- the end -------------------------------------------------------------------------------
    def finish(self) -> Path:
        """Write the remaining messages and the summary, fsync, rename to the final name."""
        if self._finished:
            return self.path
        self._finished = True
        self._queue.put(_STOP)
        self._thread.join()
        if self._error is not None:
            self._stream.close()
            self._raise_error()
        try:
            self._mcap.finish()
            self._stream.flush()
            os.fsync(self._stream.fileno())
            self._stream.close()
            os.replace(self.partial, self.path)
        except OSError as err:
            raise LogFormatError(f"{self.partial}: cannot finish ({err.strerror})") from err
        _fsync_directory(self.path.parent)
        return self.path

    def __enter__(self) -> LogWriter:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.finish()


def _fsync_directory(directory: Path) -> None:
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
