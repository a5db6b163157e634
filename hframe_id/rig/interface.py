"""The one driver interface every rig backend implements (``sim``, ``serial``).

A rig samples at a fixed period on its own clock. ``read()`` returns the next sample (sequence
number, device timestamp, encoder counts, laser readings with validity, limit switches, the
voltages applied over the interval that ended at the sample); ``set_voltages(sequence, volts)``
commands the voltages to hold from that sample until the next (zero-order hold, the timing
convention of ``hframe_id.recordings.recording``). Voltages are clamped to the DAC range and
quantized by the rig; ``stop()`` always leaves the outputs at 0 V.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hframe_id.recordings.log_format import LIMIT_SWITCHES
from hframe_id.recordings.sensors import ENCODER_OUTPUTS, LASER_OUTPUTS, SensorModel
from hframe_id.recordings.writer import Attachment


@dataclass(frozen=True)
class RigInfo:
    """What a rig is: the ``rig`` metadata record of its recordings.

    Attributes
    ----------
    variant : model variant the rig is (``one-axis``, ``hframe-8`` ...).
    backend : ``"sim"`` or ``"serial"``.
    sample_period_s : the device's sample period [s].
    inputs, outputs : input and output names (``u1``, ``u2``; ``phi1``, ``phi2``, ``x``, ``y``).
    sensors : encoder, DAC and laser characteristics.
    pulley_radius_m : motor pulley radius [m] (None if unknown).
    amplifier_gains : volts at the motor per volt commanded, per motor (None if unknown).
    travel_m : per axis, the positions [m] of the (min, max) limit switches.
    serial_number, firmware : identification of the device (or of the simulation).
    extra : further metadata (seed, parameter file, port ...).
    """

    variant: str
    backend: str
    sample_period_s: float
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    sensors: SensorModel
    pulley_radius_m: float | None = None
    amplifier_gains: tuple[float, ...] | None = None
    travel_m: dict[str, tuple[float, float]] = field(default_factory=dict)
    serial_number: str = ""
    firmware: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def encoders(self) -> tuple[str, ...]:
        """Outputs read by the motor encoders (``phi1``, ``phi2``), in output order."""
        return tuple(n for n in self.outputs if n in ENCODER_OUTPUTS)

    @property
    def lasers(self) -> tuple[str, ...]:
        """Outputs read by the laser sensors (``x``, ``y``), in output order."""
        return tuple(n for n in self.outputs if n in LASER_OUTPUTS)

    @property
    def limit_switches(self) -> tuple[str, ...]:
        """Limit switches the rig has: those of the axes with a ``travel_m`` entry."""
        return tuple(s for s in LIMIT_SWITCHES if s[0] in self.travel_m)

    @property
    def period_us(self) -> int:
        """The sample period in whole microseconds [us]."""
        return round(self.sample_period_s * 1e6)

    def metadata(self) -> dict[str, Any]:
        """The ``rig`` metadata record (see docs/log-format.md)."""
        s = self.sensors
        meta: dict[str, Any] = {
            "variant": self.variant,
            "backend": self.backend,
            "sample_period_s": self.sample_period_s,
            "inputs": list(self.inputs),
            "outputs": list(self.outputs),
            **s.as_metadata(),
            "pulley_radius_m": self.pulley_radius_m,
            "serial_number": self.serial_number,
            "firmware": self.firmware,
        }
        for i, gain in enumerate(self.amplifier_gains or (), start=1):
            meta[f"amplifier_gain_{i}"] = gain
        for axis, (low, high) in self.travel_m.items():
            meta[f"limit_{axis}_min_m"] = low
            meta[f"limit_{axis}_max_m"] = high
        meta.update(self.extra)
        return meta


@dataclass(frozen=True)
class RigSample:
    """One sample as the device reports it.

    Attributes
    ----------
    sequence : device sample counter.
    device_time_us : device clock [us] since sampling started.
    encoder_counts : per encoder (``RigInfo.encoders`` order) [counts].
    laser_m : per laser (``RigInfo.lasers`` order) [m]; NaN before the first valid reading.
    laser_valid : per laser, target inside the measuring range.
    limits : per limit switch (``RigInfo.limit_switches``), closed.
    applied_v : voltages the DAC output over the interval that ended at this sample [V].
    command_sequence : sequence of the command in force over that interval (None: none yet).
    watchdog : the device watchdog has dropped the outputs to 0 V.
    received_s : host ``time.perf_counter()`` when the sample reached the host [s].
    """

    sequence: int
    device_time_us: int
    encoder_counts: tuple[int, ...]
    laser_m: tuple[float, ...]
    laser_valid: tuple[bool, ...]
    limits: dict[str, bool]
    applied_v: tuple[float, ...]
    command_sequence: int | None
    watchdog: bool
    received_s: float


@dataclass
class LinkStats:
    """Link health counters a backend keeps (zero for the sim rig)."""

    crc_errors: int = 0
    frames_received: int = 0
    frames_sent: int = 0
    bytes_discarded: int = 0


class Rig(ABC):
    """A rig: start, then alternately ``read()`` a sample and ``set_voltages()`` for it."""

    info: RigInfo
    stats: LinkStats

    @abstractmethod
    def start(self) -> None:
        """Start sampling (outputs at 0 V until the first command)."""

    @abstractmethod
    def read(self) -> RigSample:
        """The next sample; blocks until it is due. Raises ``RigFault`` on a link fault."""

    @abstractmethod
    def set_voltages(self, sequence: int, volts: Sequence[float]) -> None:
        """Command ``volts`` [V] (one per input) to hold from sample ``sequence`` on."""

    @abstractmethod
    def stop(self) -> None:
        """Set 0 V and stop sampling. Safe to call more than once and after a fault."""

    def attachments(self) -> list[Attachment]:
        """Files its recordings carry (the sim rig: its plant parameter file)."""
        return []

    def close(self) -> None:
        """Release the rig (stops it first)."""
        self.stop()

    def zero(self) -> np.ndarray:
        """Zero voltages [V], one per input."""
        return np.zeros(len(self.info.inputs))

    def __enter__(self) -> Rig:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
