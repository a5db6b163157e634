"""The ``serial`` rig: a microcontroller runs the real-time loop; the host talks to it over a
serial link (USB CDC) with the framed protocol of ``serial_protocol`` (docs/serial-protocol.md).

The device samples on its own clock and streams one SAMPLE frame per period; the host answers
each with a COMMAND frame carrying the sample's sequence number. The device applies the newest
command at its next tick and drops the outputs to 0 V by itself if no command came for
``watchdog_ms``. The host declares a link fault (``RigFault``) when no sample arrives for
``link_timeout_s`` or the port fails (disconnect); corrupted frames are counted and skipped
(the lost samples show up as sequence gaps).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np
import serial

from hframe_id.errors import OptionError, RigFault
from hframe_id.recordings.sensors import SensorModel
from hframe_id.rig import serial_protocol as sp
from hframe_id.rig.interface import LinkStats, Rig, RigInfo, RigSample


class SerialRig(Rig):
    """A rig behind a serial port.

    Parameters
    ----------
    port : device path (``/dev/ttyACM0``, or the emulator's pseudo-terminal).
    baudrate : line rate (USB CDC ignores it).
    watchdog_ms : device watchdog: 0 V after this long without a command [ms].
    link_timeout_s : link fault after this long without a sample [s].
    hello_timeout_s : how long to wait for the device to identify itself [s].
    """

    def __init__(
        self,
        port: str,
        *,
        baudrate: int = 2_000_000,
        watchdog_ms: int = 50,
        link_timeout_s: float = 0.1,
        hello_timeout_s: float = 2.0,
    ) -> None:
        if not 1 <= watchdog_ms <= 60_000:
            raise OptionError(f"watchdog must be 1..60000 ms, got {watchdog_ms}")
        if not (math.isfinite(link_timeout_s) and link_timeout_s > 0):
            raise OptionError(f"link timeout must be > 0 s, got {link_timeout_s}")
        self.port = port
        self.watchdog_ms = int(watchdog_ms)
        self.link_timeout_s = float(link_timeout_s)
        self.stats = LinkStats()
        self._decoder = sp.Decoder()
        self._samples: list[RigSample] = []
        self._running = False
        try:
            self._serial = serial.Serial(port, baudrate=baudrate, timeout=0.01, write_timeout=0.5)
        except (serial.SerialException, OSError, ValueError) as err:
            raise RigFault(f"{port}: cannot open the serial port ({err})") from None
        try:
            self.info = self._hello(hello_timeout_s)
        except BaseException:
            self._serial.close()
            raise

    # -- link ------------------------------------------------------------------------------------
    def _send(self, frame_type: int, payload: bytes = b"") -> None:
        try:
            self._serial.write(sp.encode(frame_type, payload))
        except (serial.SerialException, OSError) as err:
            raise RigFault(f"{self.port}: serial link lost while sending ({err})") from None
        self.stats.frames_sent += 1

    def _receive(self, timeout_s: float) -> list[tuple[int, bytes]]:
        """Frames that arrive within ``timeout_s`` (returns as soon as there are some)."""
        deadline = time.perf_counter() + timeout_s
        while True:
            try:
                waiting = self._serial.in_waiting
                data = self._serial.read(waiting or 1)
            except (serial.SerialException, OSError, TypeError) as err:
                raise RigFault(f"{self.port}: serial link lost ({err})") from None
            frames = self._decoder.feed(data) if data else []
            self.stats.crc_errors = self._decoder.crc_errors
            self.stats.bytes_discarded = self._decoder.bytes_discarded
            if frames:
                self.stats.frames_received += len(frames)
                return frames
            if time.perf_counter() >= deadline:
                return []

    def _hello(self, timeout_s: float) -> RigInfo:
        self._serial.reset_input_buffer()
        deadline = time.perf_counter() + timeout_s
        while time.perf_counter() < deadline:
            self._send(sp.HELLO)
            for frame_type, payload in self._receive(0.2):
                if frame_type == sp.INFO:
                    return self._rig_info(sp.decode_info(payload, f"{self.port}: INFO frame"))
        raise RigFault(f"{self.port}: no answer to HELLO within {timeout_s} s (is it the rig?)")

    def _rig_info(self, info: dict) -> RigInfo:
        try:
            if info["protocol_version"] != sp.PROTOCOL_VERSION:
                raise RigFault(
                    f"{self.port}: device speaks protocol {info['protocol_version']}, "
                    f"this host {sp.PROTOCOL_VERSION}"
                )
            sensors = SensorModel(
                encoder_counts_per_rev=int(info["encoder_counts_per_rev"]),
                dac_bits=int(info["dac_bits"]),
                dac_min_v=float(info["dac_min_v"]),
                dac_max_v=float(info["dac_max_v"]),
                laser_noise_std_m=float(info.get("laser_noise_std_m", 0.0)),
                laser_min_m=float(info["laser_min_m"]),
                laser_max_m=float(info["laser_max_m"]),
            )
            return RigInfo(
                variant=str(info["variant"]),
                backend="serial",
                sample_period_s=int(info["sample_period_us"]) * 1e-6,
                inputs=tuple(info["inputs"]),
                outputs=tuple(info["outputs"]),
                sensors=sensors,
                pulley_radius_m=info.get("pulley_radius_m"),
                amplifier_gains=tuple(info["amplifier_gains"])
                if info.get("amplifier_gains")
                else None,
                travel_m={k: (float(v[0]), float(v[1])) for k, v in info["travel_m"].items()},
                serial_number=str(info["serial_number"]),
                firmware=str(info["firmware"]),
                extra={
                    "port": self.port,
                    "protocol_version": sp.PROTOCOL_VERSION,
                    "watchdog_ms": self.watchdog_ms,
                    **{f"device.{k}": v for k, v in info.get("extra", {}).items()},
                },
            )
        except (KeyError, TypeError, ValueError) as err:
            raise RigFault(f"{self.port}: malformed INFO from the device ({err!r})") from None

    # -- the rig interface -------------------------------------------------------------------------
    def start(self) -> None:
        """Send START with the period [us] and watchdog [ms]; 0 V until the first command."""
        self._samples.clear()
        self._zero_codes = self.info.sensors.dac_code(np.zeros(2))
        self._send(sp.START, sp.START_PAYLOAD.pack(self.info.period_us, self.watchdog_ms))
        self._running = True

    def read(self) -> RigSample:
        """The next sample; ``RigFault`` on a device fault or when the link falls silent."""
        if not self._running:
            raise RigFault(f"{self.port}: read() before start()")
        deadline = time.perf_counter() + self.link_timeout_s
        while not self._samples:
            remaining = deadline - time.perf_counter()
            if remaining <= 0:
                raise RigFault(
                    f"{self.port}: no sample for {self.link_timeout_s * 1e3:.0f} ms "
                    "(device stopped answering)"
                )
            frames = self._receive(remaining)
            received = time.perf_counter()
            for frame_type, payload in frames:
                if frame_type == sp.SAMPLE and len(payload) == sp.SAMPLE_PAYLOAD.size:
                    self._samples.append(self._sample(payload, received))
                elif frame_type == sp.FAULT:
                    raise RigFault(f"{self.port}: device fault: {payload.decode(errors='replace')}")
        return self._samples.pop(0)

    def _sample(self, payload: bytes, received: float) -> RigSample:
        (seq, time_us, enc1, enc2, laser_x, laser_y, flags, code1, code2, cmd) = (
            sp.SAMPLE_PAYLOAD.unpack(payload)
        )
        info = self.info
        counts = {"phi1": enc1, "phi2": enc2}
        lasers = {
            "x": (laser_x, flags & sp.LASER_X_VALID, flags & sp.LASER_X_NONE),
            "y": (laser_y, flags & sp.LASER_Y_VALID, flags & sp.LASER_Y_NONE),
        }
        volts = info.sensors.dac_volts(np.array([code1, code2]))
        return RigSample(
            sequence=seq,
            device_time_us=time_us,
            encoder_counts=tuple(counts[n] for n in info.encoders),
            laser_m=tuple(math.nan if lasers[a][2] else lasers[a][0] * 1e-9 for a in info.lasers),
            laser_valid=tuple(bool(lasers[a][1]) for a in info.lasers),
            limits={s: bool(flags & sp.LIMIT_BITS[s]) for s in info.limit_switches},
            applied_v=tuple(float(v) for v in volts[: len(info.inputs)]),
            command_sequence=None if cmd == sp.NO_COMMAND else cmd,
            watchdog=bool(flags & sp.WATCHDOG),
            received_s=received,
        )

    def set_voltages(self, sequence: int, volts: Sequence[float]) -> None:
        """Send ``volts`` [V] (one per input) as DAC codes, to hold from sample ``sequence`` on."""
        volts = np.asarray(volts, dtype=float)
        if volts.shape != (len(self.info.inputs),):
            raise OptionError(
                f"{self.info.variant} takes {len(self.info.inputs)} voltage(s), got {volts.shape}"
            )
        codes = self._zero_codes.copy()
        codes[: volts.size] = self.info.sensors.dac_code(volts)
        self._send(sp.COMMAND, sp.COMMAND_PAYLOAD.pack(sequence, int(codes[0]), int(codes[1])))

    def stop(self) -> None:
        """Command 0 V and STOP, and wait briefly for STOPPED; safe after a link fault."""
        if not self._running:
            return
        self._running = False
        try:
            self._send(sp.COMMAND, sp.COMMAND_PAYLOAD.pack(0, *(int(c) for c in self._zero_codes)))
            self._send(sp.STOP)
            deadline = time.perf_counter() + 0.2
            while time.perf_counter() < deadline:
                if any(t == sp.STOPPED for t, _ in self._receive(0.05)):
                    break
        except RigFault:
            pass  # the link is gone; the device watchdog has dropped the outputs

    def close(self) -> None:
        """Stop the device and close the serial port."""
        self.stop()
        self._serial.close()
