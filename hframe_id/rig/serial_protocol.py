"""The framed binary protocol between the host and the rig microcontroller (serial-protocol.md).

Frame: ``A5 5A | type u8 | length u16 | payload | crc u16`` (little endian), the CRC being
CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) over type, length and payload. A receiver that
finds a bad CRC or an impossible length drops one byte and searches for the next sync word, so
a corrupted frame costs that frame only.
"""

from __future__ import annotations

import binascii
import json
import struct
from dataclasses import dataclass
from typing import Any

from hframe_id.documents import load_json
from hframe_id.errors import RigFault

PROTOCOL_VERSION = 1
SYNC = b"\xa5\x5a"
HEAD = struct.Struct("<2sBH")
CRC = struct.Struct("<H")
MAX_PAYLOAD = 1024

# Host -> device
HELLO = 0x01
START = 0x02
COMMAND = 0x03
STOP = 0x04
# Device -> host
INFO = 0x81
SAMPLE = 0x82
STOPPED = 0x83
FAULT = 0x84

START_PAYLOAD = struct.Struct("<IH")  # sample period [us], watchdog [ms]
COMMAND_PAYLOAD = struct.Struct("<IHH")  # sequence, DAC code motor 1, DAC code motor 2
#: sequence, device time [us], encoder 1 and 2 [counts], laser x and y [nm], flags, applied
#: DAC codes of motors 1 and 2, sequence of the command in force (NO_COMMAND: none yet).
SAMPLE_PAYLOAD = struct.Struct("<IQiiiiHHHI")
NO_COMMAND = 0xFFFFFFFF

# SAMPLE flags
LASER_X_VALID = 1 << 0
LASER_Y_VALID = 1 << 1
LIMIT_BITS = {"x_min": 1 << 2, "x_max": 1 << 3, "y_min": 1 << 4, "y_max": 1 << 5}
WATCHDOG = 1 << 6
LASER_X_NONE = 1 << 7  # no valid reading yet: the value field means nothing
LASER_Y_NONE = 1 << 8


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE."""
    return binascii.crc_hqx(data, 0xFFFF)


def encode(frame_type: int, payload: bytes = b"") -> bytes:
    """One frame: sync, type, payload length, ``payload``, CRC-16 of type to payload.

    Raises ValueError if the payload exceeds ``MAX_PAYLOAD`` bytes.
    """
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(f"payload of {len(payload)} bytes exceeds {MAX_PAYLOAD}")
    head = HEAD.pack(SYNC, frame_type, len(payload))
    return head + payload + CRC.pack(crc16(head[2:] + payload))


@dataclass
class Decoder:
    """Incremental frame decoder: feed bytes, get (type, payload) frames back."""

    crc_errors: int = 0
    bytes_discarded: int = 0

    def __post_init__(self) -> None:
        self._buffer = bytearray()

    def feed(self, data: bytes) -> list[tuple[int, bytes]]:
        """Append ``data`` and return the complete frames in it as (frame type, payload).

        Bytes before a sync word and frames with a bad CRC or length are skipped (counted in
        ``bytes_discarded`` and ``crc_errors``); an incomplete frame waits for the next call.
        """
        buffer = self._buffer
        buffer += data
        frames = []
        while True:
            start = buffer.find(SYNC)
            if start < 0:
                keep = 1 if buffer[-1:] == SYNC[:1] else 0
                self.bytes_discarded += len(buffer) - keep
                del buffer[: len(buffer) - keep]
                break
            if start:
                self.bytes_discarded += start
                del buffer[:start]
            if len(buffer) < HEAD.size:
                break
            _, frame_type, length = HEAD.unpack_from(buffer)
            if length > MAX_PAYLOAD:
                self.crc_errors += 1
                self.bytes_discarded += 1
                del buffer[:1]
                continue
            end = HEAD.size + length + CRC.size
            if len(buffer) < end:
                break
            (crc,) = CRC.unpack_from(buffer, end - CRC.size)
            if crc != crc16(bytes(buffer[2 : end - CRC.size])):
                self.crc_errors += 1
                self.bytes_discarded += 1
                del buffer[:1]
                continue
            frames.append((frame_type, bytes(buffer[HEAD.size : end - CRC.size])))
            del buffer[:end]
        return frames


def encode_info(info: dict[str, Any]) -> bytes:
    """An INFO frame carrying ``info`` as compact JSON."""
    return encode(INFO, json.dumps(info, separators=(",", ":")).encode())


def decode_info(payload: bytes, where: str = "INFO frame") -> dict[str, Any]:
    """The JSON record of an INFO frame's payload (``RigFault`` naming ``where`` if it is not
    JSON, or beyond the limits of ``hframe_id.documents``)."""
    return load_json(payload, where, RigFault)
