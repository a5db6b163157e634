"""Sensor and actuator models of the thesis's rig (section 1.1, 3.4), shared by every sim path.

- DAC: 12 bit over +/-10 V; commands are clamped to the range and rounded to the DAC step.
- Encoders: 321084 counts per motor revolution; the count is the floor of the angle in counts
  plus a random sub-count phase fixed at power-up (so quantization error is not centred).
- Lasers (optoNCDT): Gaussian noise; a measuring range of about 10 cm, beyond which the sensor
  keeps reporting its last valid value (section 3.4). The rig marks such samples invalid.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from hframe_id.errors import OptionError


@dataclass(frozen=True)
class SensorModel:
    """Rig sensor and DAC characteristics (SI).

    Attributes
    ----------
    encoder_counts_per_rev : encoder resolution at the motor shaft [counts/rev].
    dac_bits, dac_min_v, dac_max_v : DAC resolution and range [V].
    laser_noise_std_m : standard deviation of laser noise [m].
    laser_min_m, laser_max_m : measuring range of each laser (x and y alike) [m].
    """

    encoder_counts_per_rev: int = 321084
    dac_bits: int = 12
    dac_min_v: float = -10.0
    dac_max_v: float = 10.0
    laser_noise_std_m: float = 5e-6
    laser_min_m: float = -0.05
    laser_max_m: float = 0.05

    def __post_init__(self) -> None:
        if self.encoder_counts_per_rev < 1:
            raise OptionError(f"encoder_counts_per_rev must be >= 1, got {self.encoder_counts_per_rev}")
        if not 1 <= self.dac_bits <= 32:
            raise OptionError(f"dac_bits must be in 1..32, got {self.dac_bits}")
        if not self.dac_min_v < self.dac_max_v:
            raise OptionError(f"DAC range must have min < max, got {self.dac_min_v}, {self.dac_max_v}")
        if not (math.isfinite(self.laser_noise_std_m) and self.laser_noise_std_m >= 0):
            raise OptionError(f"laser_noise_std_m must be >= 0, got {self.laser_noise_std_m}")
        if not self.laser_min_m < self.laser_max_m:
            raise OptionError(f"laser range must have min < max, got {self.laser_min_m}, {self.laser_max_m}")

    @property
    def encoder_step_rad(self) -> float:
        """Angle of one encoder count [rad]."""
        return 2 * math.pi / self.encoder_counts_per_rev

    @property
    def dac_step_v(self) -> float:
        """Voltage of one DAC step [V]."""
        return (self.dac_max_v - self.dac_min_v) / (2**self.dac_bits - 1)

    @property
    def encoder_noise_std_rad(self) -> float:
        """Standard deviation of uniform quantization error [rad]: step / sqrt(12)."""
        return self.encoder_step_rad / math.sqrt(12)

    def as_metadata(self) -> dict[str, float | int]:
        return asdict(self)

    def dac(self, volts: np.ndarray) -> np.ndarray:
        """Commanded voltages as the DAC outputs them: clamped and rounded to a DAC step."""
        clamped = np.clip(np.asarray(volts, dtype=float), self.dac_min_v, self.dac_max_v)
        steps = np.round((clamped - self.dac_min_v) / self.dac_step_v)
        return self.dac_min_v + steps * self.dac_step_v

    def encoder_counts(self, angle_rad: np.ndarray, phase: np.ndarray) -> np.ndarray:
        """Counts of encoders at ``angle_rad`` with power-up sub-count ``phase`` in [0, 1)."""
        return np.floor(np.asarray(angle_rad) / self.encoder_step_rad + phase) - np.floor(phase)

    def laser(
        self, position_m: np.ndarray, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray]:
        """Laser readings of one axis over time and their validity.

        Inside the range: position plus noise. Outside: the last valid reading is held (NaN if
        the sensor has not seen the target yet) and the sample is marked invalid.
        """
        position_m = np.asarray(position_m, dtype=float)
        noisy = position_m + self.laser_noise_std_m * rng.standard_normal(position_m.shape)
        valid = (position_m >= self.laser_min_m) & (position_m <= self.laser_max_m)
        reading = np.where(valid, noisy, np.nan)
        held = _hold_last(reading)
        return held, valid


def _hold_last(values: np.ndarray) -> np.ndarray:
    """Forward-fill NaNs with the last finite value along axis 0."""
    index = np.where(np.isfinite(values), np.arange(values.shape[0]), 0)
    np.maximum.accumulate(index, out=index)
    filled = values[index]
    if not np.isfinite(values[0]):
        first_valid = np.argmax(np.isfinite(values)) if np.isfinite(values).any() else values.size
        filled[:first_valid] = np.nan
    return filled
