"""Sensor and actuator models of the thesis's rig (section 1.1, 3.4), shared by every sim path.

- DAC: 12 bit over +/-10 V, offset binary: code 0 is -10 V, code 2^12 - 1 is 10 V - 1 LSB, so
  that 0 V (code 2048) is exact (a safety stop must really be 0 V). Commands are clamped to
  the range and rounded to the nearest code.
- Encoders: 321084 counts per motor revolution; the count is the floor of the angle in counts
  plus a random sub-count phase fixed at power-up (so quantization error is not centred).
- Lasers (optoNCDT): Gaussian noise; a measuring range of about 10 cm, beyond which the sensor
  keeps reporting its last valid value (section 3.4). The rig marks such samples invalid.

Random numbers are drawn in one fixed order, so that the batch path
(``hframe_id.recordings.simulated``) and the sample-by-sample ``sim`` rig give the same
recording from the same seed: first one power-up phase per encoder (in output order), then,
per sample, one standard normal per laser (in output order).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from hframe_id.errors import OptionError

#: Output names measured by encoders (motor angles [rad]) and by lasers (positions [m]).
ENCODER_OUTPUTS = ("phi1", "phi2")
LASER_OUTPUTS = ("x", "y")


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
            raise OptionError(
                f"encoder_counts_per_rev must be >= 1, got {self.encoder_counts_per_rev}"
            )
        if not 1 <= self.dac_bits <= 32:
            raise OptionError(f"dac_bits must be in 1..32, got {self.dac_bits}")
        if not self.dac_min_v < self.dac_max_v:
            raise OptionError(
                f"DAC range must have min < max, got {self.dac_min_v}, {self.dac_max_v}"
            )
        if not (math.isfinite(self.laser_noise_std_m) and self.laser_noise_std_m >= 0):
            raise OptionError(f"laser_noise_std_m must be >= 0, got {self.laser_noise_std_m}")
        if not self.laser_min_m < self.laser_max_m:
            raise OptionError(
                f"laser range must have min < max, got {self.laser_min_m}, {self.laser_max_m}"
            )

    @property
    def encoder_step_rad(self) -> float:
        """Angle of one encoder count [rad]."""
        return 2 * math.pi / self.encoder_counts_per_rev

    @property
    def dac_step_v(self) -> float:
        """Voltage of one DAC step [V] (offset binary: span / 2^bits)."""
        return (self.dac_max_v - self.dac_min_v) / 2**self.dac_bits

    def as_metadata(self) -> dict[str, float | int]:
        """The sensor fields of the ``rig`` metadata record, in the log format's order."""
        order = ("encoder_counts_per_rev", "dac_bits", "dac_min_v", "dac_max_v",
                 "laser_min_m", "laser_max_m", "laser_noise_std_m")  # fmt: skip
        values = asdict(self)
        return {name: values[name] for name in order}

    def dac_code(self, volts: np.ndarray) -> np.ndarray:
        """DAC codes (integers 0 .. 2^bits - 1) of commanded voltages, clamped to the range."""
        clamped = np.clip(np.asarray(volts, dtype=float), self.dac_min_v, self.dac_max_v)
        codes = np.round((clamped - self.dac_min_v) / self.dac_step_v)
        return np.clip(codes, 0, 2**self.dac_bits - 1).astype(np.int64)

    def dac_volts(self, codes: np.ndarray) -> np.ndarray:
        """Voltage [V] the DAC outputs for ``codes``."""
        return self.dac_min_v + np.asarray(codes, dtype=float) * self.dac_step_v

    def dac(self, volts: np.ndarray) -> np.ndarray:
        """Commanded voltages as the DAC outputs them: clamped and rounded to a DAC step."""
        return self.dac_volts(self.dac_code(volts))

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
        return self.laser_from_noise(position_m, rng.standard_normal(position_m.shape))

    def laser_from_noise(
        self, position_m: np.ndarray, noise: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """As ``laser`` with the standard normal draws given (same shape as ``position_m``)."""
        position_m = np.asarray(position_m, dtype=float)
        noisy = position_m + self.laser_noise_std_m * np.asarray(noise, dtype=float)
        valid = (position_m >= self.laser_min_m) & (position_m <= self.laser_max_m)
        reading = np.where(valid, noisy, np.nan)
        return _hold_last(reading), valid


def split_outputs(output_names: tuple[str, ...]) -> tuple[list[int], list[int]]:
    """Column indices of the encoder outputs and of the laser outputs, in output order."""
    unknown = [n for n in output_names if n not in ENCODER_OUTPUTS + LASER_OUTPUTS]
    if unknown:
        raise OptionError(f"no sensor measures output(s) {', '.join(unknown)}")
    encoders = [i for i, n in enumerate(output_names) if n in ENCODER_OUTPUTS]
    lasers = [i for i, n in enumerate(output_names) if n in LASER_OUTPUTS]
    return encoders, lasers


def measure_batch(
    sensors: SensorModel,
    output_names: tuple[str, ...],
    true_outputs: np.ndarray,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Measured outputs (SI, NaN where no reading) and validity of a whole (N, n_y) record."""
    encoders, lasers = split_outputs(output_names)
    phases = rng.uniform(size=len(encoders))
    noise = rng.standard_normal((true_outputs.shape[0], len(lasers)))
    outputs = np.empty_like(true_outputs, dtype=float)
    valid = np.ones(true_outputs.shape, dtype=bool)
    for j, column in enumerate(encoders):
        counts = sensors.encoder_counts(true_outputs[:, column], phases[j])
        outputs[:, column] = counts * sensors.encoder_step_rad
    for j, column in enumerate(lasers):
        outputs[:, column], valid[:, column] = sensors.laser_from_noise(
            true_outputs[:, column], noise[:, j]
        )
    return outputs, valid


class SensorReadout:
    """The rig's sensors read sample by sample (the ``sim`` rig); equal to ``measure_batch``.

    Parameters
    ----------
    sensors : sensor characteristics.
    output_names : the model's outputs, in order (encoders ``phi*``, lasers ``x``/``y``).
    rng : random generator, seeded by the caller; the power-up phases are drawn here.
    """

    def __init__(
        self, sensors: SensorModel, output_names: tuple[str, ...], rng: np.random.Generator
    ) -> None:
        self.sensors = sensors
        self.output_names = tuple(output_names)
        self.encoder_columns, self.laser_columns = split_outputs(self.output_names)
        self._rng = rng
        self._phases = rng.uniform(size=len(self.encoder_columns))
        self._held = np.full(len(self.laser_columns), np.nan)

    def read(self, true_outputs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Encoder counts, laser readings [m] (NaN before the first valid one) and validity."""
        s = self.sensors
        y = np.asarray(true_outputs, dtype=float)
        counts = s.encoder_counts(y[self.encoder_columns], self._phases).astype(np.int64)
        position = y[self.laser_columns]
        noise = self._rng.standard_normal(len(self.laser_columns))
        valid = (position >= s.laser_min_m) & (position <= s.laser_max_m)
        self._held = np.where(valid, position + s.laser_noise_std_m * noise, self._held)
        return counts, self._held.copy(), valid


def _hold_last(values: np.ndarray) -> np.ndarray:
    """Forward-fill NaNs with the last finite value along axis 0."""
    index = np.where(np.isfinite(values), np.arange(values.shape[0]), 0)
    np.maximum.accumulate(index, out=index)
    filled = values[index]
    if not np.isfinite(values[0]):
        first_valid = np.argmax(np.isfinite(values)) if np.isfinite(values).any() else values.size
        filled[:first_valid] = np.nan
    return filled
