"""Open-loop input sequences: steps and pulses per motor, zero-order held at the sample time.

A sequence is an (N, n_u) table of voltages [V]; row k is commanded at t_k = k T and held until
t_{k+1} (the D/A converter, section 5.3). Edges fall on whole samples: an edge at time t acts
from the first sample k with k T >= t (to within 1e-9 T, so 0.1 s at 1 ms is sample 100).
Voltage sequences from CSV use the recorder's format (``hframe_id.rig.protocols``:
``time [s],u1 [V][,u2 [V]]``), recordings their commanded voltages.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hframe_id.errors import OptionError


@dataclass(frozen=True)
class MotorStep:
    """A step (``duration_s`` None) or pulse of one motor's voltage.

    Attributes
    ----------
    motor : 1-based motor index.
    amplitude_v : voltage during the step [V].
    start_s : when the step starts [s].
    duration_s : how long it lasts [s]; None: until the end of the run.
    """

    motor: int
    amplitude_v: float
    start_s: float = 0.0
    duration_s: float | None = None

    def __post_init__(self) -> None:
        if isinstance(self.motor, bool) or not isinstance(self.motor, int) or self.motor < 1:
            raise OptionError(f"motor must be 1, 2, ..., got {self.motor!r}")
        if not math.isfinite(self.amplitude_v):
            raise OptionError(f"step amplitude must be finite, got {self.amplitude_v!r}")
        if not (math.isfinite(self.start_s) and self.start_s >= 0):
            raise OptionError(f"step start must be a time >= 0 s, got {self.start_s!r}")
        if self.duration_s is not None and not (
            math.isfinite(self.duration_s) and self.duration_s > 0
        ):
            raise OptionError(f"step duration must be > 0 s, got {self.duration_s!r}")

    @classmethod
    def parse(cls, text: str) -> MotorStep:
        """``MOTOR,VOLTS[,START_S[,DURATION_S]]``, e.g. ``1,4`` or ``2,-6,0.05,0.25``."""
        parts = [part.strip() for part in str(text).split(",")]
        if not 2 <= len(parts) <= 4:
            raise OptionError(
                f"step {text!r}: expected MOTOR,VOLTS[,START_S[,DURATION_S]], e.g. 1,4,0.05,0.25"
            )
        try:
            motor = int(parts[0])
            numbers = [float(part) for part in parts[1:]]
        except ValueError:
            raise OptionError(
                f"step {text!r}: MOTOR must be an integer and the rest numbers"
            ) from None
        return cls(motor, *numbers)


def _first_sample(t_s: float, dt: float) -> int:
    return int(math.ceil(t_s / dt - 1e-9))


def step_inputs(
    steps: Sequence[MotorStep], n_inputs: int, duration_s: float, dt: float = 1e-3
) -> np.ndarray:
    """(N, n_inputs) held voltages for ``duration_s`` [s]: the sum of ``steps`` (0 V elsewhere)."""
    if not (math.isfinite(dt) and dt > 0):
        raise OptionError(f"sample time must be > 0 s, got {dt!r}")
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise OptionError(f"duration must be > 0 s, got {duration_s!r}")
    n = int(round(duration_s / dt))
    if n < 1:
        raise OptionError(f"duration {duration_s} s is shorter than one sample of {dt} s")
    table = np.zeros((n, n_inputs))
    for step in steps:
        if step.motor > n_inputs:
            raise OptionError(f"step on motor {step.motor}, but the model has {n_inputs} motor(s)")
        begin = _first_sample(step.start_s, dt)
        end = n if step.duration_s is None else _first_sample(step.start_s + step.duration_s, dt)
        if begin >= n:
            raise OptionError(
                f"step on motor {step.motor} starts at {step.start_s} s, after the end of the "
                f"run ({duration_s} s)"
            )
        table[begin:end, step.motor - 1] += step.amplitude_v
    return table


def change_points(table: np.ndarray, dt: float) -> tuple[tuple[float, ...], tuple[tuple, ...]]:
    """(times [s], voltages) of the rows where ``table`` changes: a compact sequence protocol."""
    table = np.atleast_2d(table)
    rows = [0, *(k for k in range(1, table.shape[0]) if not np.array_equal(table[k], table[k - 1]))]
    return tuple(k * dt for k in rows), tuple(tuple(float(v) for v in table[k]) for k in rows)
