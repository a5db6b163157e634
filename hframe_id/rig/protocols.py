"""Experiment protocols: which voltage to command at each sample.

A protocol turns into a table of voltages, one row per sample index k (time k T), so that
edges fall on whole samples whatever the float rounding of k T. Three kinds:

- ``StepProtocol``: a voltage step per motor (the H-frame experiments of section 4.4): 0 V for
  ``pre_roll_s``, then ``voltages_v`` for ``step_s``, then 0 V until ``duration_s``.
- ``PulseProtocol``: one motor, one amplitude for ``width_s`` (the one-axis tests, section 2.3:
  0.25 s pulses of 5 V and 10 V).
- ``SequenceProtocol``: an arbitrary sequence read from CSV (``time [s]``, ``u1 [V]``[, ``u2
  [V]``]), held from each row's time to the next one's.
- ``MultisineProtocol``: a seeded, band-limited random-phase multisine per motor (a richer
  excitation than steps, docs/realistic-rig.md).
"""

from __future__ import annotations

import csv
import hashlib
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hframe_id.documents import open_input
from hframe_id.errors import OptionError, shown


def _samples(name: str, seconds: float, period_s: float, minimum: int = 0) -> int:
    if not math.isfinite(seconds) or seconds < 0:
        raise OptionError(f"{name} must be a finite time >= 0 s, got {seconds}")
    n = round(seconds / period_s)
    if abs(n * period_s - seconds) > 1e-9 + 1e-6 * seconds:
        raise OptionError(
            f"{name} {seconds} s is not a whole number of {period_s * 1e3:g} ms samples"
        )
    if n < minimum:
        raise OptionError(f"{name} must be at least {minimum} sample(s), got {seconds} s")
    return n


def _check_volts(name: str, value: float) -> float:
    if not isinstance(value, int | float) or not math.isfinite(value):
        raise OptionError(f"{name} must be a finite voltage, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class StepProtocol:
    """A voltage step on every motor at once.

    Attributes
    ----------
    voltages_v : step voltage per motor [V] (one entry per rig input).
    step_s : how long the step lasts [s].
    duration_s : record duration [s] (samples at 0, T, ..., duration - T).
    pre_roll_s : 0 V recorded before the step [s].
    """

    voltages_v: tuple[float, ...]
    step_s: float
    duration_s: float
    pre_roll_s: float = 0.05
    name: str = field(default="step", init=False)

    def __post_init__(self) -> None:
        if not self.voltages_v:
            raise OptionError("a step needs at least one motor voltage")
        for i, v in enumerate(self.voltages_v, start=1):
            _check_volts(f"step voltage of motor {i}", v)
        for label, value in (
            ("step", self.step_s),
            ("duration", self.duration_s),
            ("pre-roll", self.pre_roll_s),
        ):
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
                raise OptionError(f"{label} must be a finite time >= 0 s, got {value!r}")
        if self.pre_roll_s + self.step_s > self.duration_s + 1e-12:
            raise OptionError(
                f"pre-roll {self.pre_roll_s} s + step {self.step_s} s must fit in the record "
                f"duration {self.duration_s} s"
            )

    @property
    def n_inputs(self) -> int:
        """Motors the step drives, one per entry of ``voltages_v``."""
        return len(self.voltages_v)

    def table(self, period_s: float) -> np.ndarray:
        """(N, n_u) voltages [V], row k commanded after sample k."""
        n = _samples("duration", self.duration_s, period_s, minimum=1)
        start = _samples("pre-roll", self.pre_roll_s, period_s)
        width = _samples("step", self.step_s, period_s)
        table = np.zeros((n, self.n_inputs))
        table[start : start + width] = self.voltages_v
        return table

    def metadata(self) -> dict[str, Any]:
        """The ``protocol.*`` fields: voltage per motor [V], step, duration, pre-roll [s]."""
        meta: dict[str, Any] = {"protocol": self.name}
        for i, v in enumerate(self.voltages_v, start=1):
            meta[f"protocol.v{i}_V"] = v
        meta.update(
            {
                "protocol.step_s": self.step_s,
                "protocol.duration_s": self.duration_s,
                "protocol.pre_roll_s": self.pre_roll_s,
            }
        )
        return meta


@dataclass(frozen=True)
class PulseProtocol:
    """A voltage pulse on one motor (the others at 0 V).

    Attributes
    ----------
    amplitude_v : pulse voltage [V].
    width_s : pulse length [s] (0.25 s in section 2.3).
    duration_s : record duration [s].
    pre_roll_s : 0 V recorded before the pulse [s].
    motor : which motor (1-based).
    n_inputs : motors of the rig.
    """

    amplitude_v: float
    width_s: float
    duration_s: float
    pre_roll_s: float = 0.05
    motor: int = 1
    n_inputs: int = 1
    name: str = field(default="pulse", init=False)

    def __post_init__(self) -> None:
        _check_volts("pulse amplitude", self.amplitude_v)
        if not 1 <= self.motor <= self.n_inputs:
            raise OptionError(
                f"pulse motor must be in 1..{self.n_inputs} on this rig, got {self.motor}"
            )
        StepProtocol((self.amplitude_v,), self.width_s, self.duration_s, self.pre_roll_s)

    def table(self, period_s: float) -> np.ndarray:
        """(N, n_inputs) voltages [V], row k commanded after sample k; other motors at 0 V."""
        single = StepProtocol(
            (self.amplitude_v,), self.width_s, self.duration_s, self.pre_roll_s
        ).table(period_s)
        table = np.zeros((single.shape[0], self.n_inputs))
        table[:, self.motor - 1] = single[:, 0]
        return table

    def metadata(self) -> dict[str, Any]:
        """The ``protocol.*`` fields: amplitude [V], width, duration, pre-roll [s], motor."""
        return {
            "protocol": self.name,
            "protocol.amplitude_V": self.amplitude_v,
            "protocol.width_s": self.width_s,
            "protocol.duration_s": self.duration_s,
            "protocol.pre_roll_s": self.pre_roll_s,
            "protocol.motor": self.motor,
        }


@dataclass(frozen=True)
class SequenceProtocol:
    """An arbitrary voltage sequence: ``voltages_v[i]`` from ``time_s[i]`` to ``time_s[i+1]``.

    The record lasts ``duration_s`` (default: the last row's time plus one sample).
    """

    time_s: tuple[float, ...]
    voltages_v: tuple[tuple[float, ...], ...]
    duration_s: float | None = None
    source: str = ""
    sha256: str = ""
    name: str = field(default="sequence", init=False)

    def __post_init__(self) -> None:
        if not self.time_s or len(self.time_s) != len(self.voltages_v):
            raise OptionError("a voltage sequence needs one row of voltages per time, >= 1 row")
        times = np.asarray(self.time_s, dtype=float)
        if not np.isfinite(times).all() or times[0] < 0 or (np.diff(times) <= 0).any():
            raise OptionError("sequence times must be finite, >= 0 and strictly increasing")
        widths = {len(row) for row in self.voltages_v}
        if len(widths) != 1:
            raise OptionError("every sequence row needs the same number of voltages")
        if not np.isfinite(np.asarray(self.voltages_v, dtype=float)).all():
            raise OptionError("sequence voltages must be finite")

    @property
    def n_inputs(self) -> int:
        """Motors the sequence drives (voltages per row)."""
        return len(self.voltages_v[0])

    def table(self, period_s: float) -> np.ndarray:
        """(N, n_inputs) voltages [V], row k the row in force at k T (0 V before the first)."""
        duration = self.duration_s
        if duration is None:
            duration = self.time_s[-1] + period_s
        n = _samples("duration", round(duration / period_s) * period_s, period_s, minimum=1)
        t = np.arange(n) * period_s
        rows = np.searchsorted(np.asarray(self.time_s), t + 1e-9 * period_s, side="right") - 1
        values = np.asarray(self.voltages_v, dtype=float)
        table = np.zeros((n, self.n_inputs))
        inside = rows >= 0
        table[inside] = values[rows[inside]]
        return table

    def metadata(self) -> dict[str, Any]:
        """The ``protocol.*`` fields: source file, its SHA-256, rows, duration [s]."""
        return {
            "protocol": self.name,
            "protocol.source": self.source,
            "protocol.sha256": self.sha256,
            "protocol.rows": len(self.time_s),
            "protocol.duration_s": self.duration_s if self.duration_s is not None else "",
        }


@dataclass(frozen=True)
class MultisineProtocol:
    """A band-limited random-phase multisine on every motor (0 V during the pre-roll).

    Component i has frequency f_i = i / period_s for f_min_hz <= f_i <= f_max_hz; the
    components are dealt out to the motors in turn (motor m gets i = m, m + n, m + 2n, ... of
    the band), so that each frequency excites one motor only and the motors' signals are
    uncorrelated over a period. Motor m's voltage is

        u_m(t) = a_m sum_{i in I_m} cos(2 pi f_i t + theta_i),  a_m = rms_v sqrt(2 / |I_m|)

    (RMS ``rms_v`` over whole periods), t from the end of the pre-roll, with phases theta_i
    drawn uniformly from [0, 2 pi) by ``numpy.random.default_rng(seed)``. Without components
    below f_min_hz the stage (an integrator from voltage to position) stays near its start.

    Attributes
    ----------
    rms_v : RMS voltage per motor [V].
    f_min_hz, f_max_hz : band [Hz].
    period_s : period [s] (frequency resolution 1 / period_s).
    duration_s : record duration [s].
    pre_roll_s : 0 V recorded first [s].
    seed : phase seed.
    n_inputs : motors of the rig.
    """

    rms_v: float
    f_min_hz: float
    f_max_hz: float
    period_s: float
    duration_s: float
    pre_roll_s: float = 0.05
    seed: int = 0
    n_inputs: int = 2
    name: str = field(default="multisine", init=False)

    def __post_init__(self) -> None:
        _check_volts("multisine rms", self.rms_v)
        for label, value in (("f_min_hz", self.f_min_hz), ("f_max_hz", self.f_max_hz),
                             ("period_s", self.period_s)):  # fmt: skip
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise OptionError(f"multisine {label} must be > 0, got {value!r}")
        if self.n_inputs < 1:
            raise OptionError(f"multisine needs >= 1 motor, got {self.n_inputs}")
        if len(self._components()) < self.n_inputs:
            raise OptionError(
                f"multisine band {self.f_min_hz}-{self.f_max_hz} Hz holds fewer than one "
                f"{1 / self.period_s:g} Hz component per motor; widen it or lengthen the period"
            )
        # the peak is at most a_m |I_m| = rms sqrt(2 |I_m|): beyond any float, the table's
        # sums overflowed to inf (numpy warnings, then inf volts clamped without a word)
        peak = abs(self.rms_v) * math.sqrt(2.0 * len(self._components()))
        if not math.isfinite(peak):
            raise OptionError(f"multisine rms {self.rms_v:g} V: its peak overflows a float")
        StepProtocol((self.rms_v,), 0.0, self.duration_s, self.pre_roll_s)

    def _components(self) -> np.ndarray:
        """Harmonic numbers i of the band (f_i = i / period_s)."""
        first = math.ceil(self.f_min_hz * self.period_s - 1e-9)
        last = math.floor(self.f_max_hz * self.period_s + 1e-9)
        return np.arange(max(first, 1), last + 1)

    def table(self, period_s: float) -> np.ndarray:
        """(N, n_inputs) voltages [V], row k commanded after sample k (0 V during the pre-roll)."""
        n = _samples("duration", self.duration_s, period_s, minimum=1)
        start = _samples("pre-roll", self.pre_roll_s, period_s)
        harmonics = self._components()
        phases = np.random.default_rng(self.seed).uniform(0.0, 2 * np.pi, harmonics.size)
        t = np.arange(n - start) * period_s
        table = np.zeros((n, self.n_inputs))
        for m in range(self.n_inputs):
            mine = slice(m, None, self.n_inputs)
            angles = np.outer(t, 2 * np.pi * harmonics[mine] / self.period_s) + phases[mine]
            amplitude = self.rms_v * math.sqrt(2.0 / harmonics[mine].size)
            table[start:, m] = amplitude * np.cos(angles).sum(axis=1)
        return table

    def metadata(self) -> dict[str, Any]:
        """The ``protocol.*`` fields: RMS [V], band [Hz], period, duration, pre-roll [s], seed."""
        return {
            "protocol": self.name,
            "protocol.rms_V": self.rms_v,
            "protocol.f_min_Hz": self.f_min_hz,
            "protocol.f_max_Hz": self.f_max_hz,
            "protocol.period_s": self.period_s,
            "protocol.duration_s": self.duration_s,
            "protocol.pre_roll_s": self.pre_roll_s,
            "protocol.seed": self.seed,
        }


def load_sequence_csv(path: str | os.PathLike, duration_s: float | None = None) -> SequenceProtocol:
    """Read a voltage sequence: header ``time [s],u1 [V][,u2 [V]]``, then one row per change."""
    path = Path(path)
    try:
        with open_input(path) as stream:
            raw = stream.read()
        if b"\0" in raw[:65536]:
            raise OptionError(f"{path}: binary data, not a CSV voltage sequence")
    except OSError as err:
        raise OptionError(f"{path}: cannot read the voltage sequence ({err.strerror})") from None
    try:
        rows = list(csv.reader(raw.decode(errors="replace").splitlines()))
    except csv.Error as err:
        raise OptionError(f"{path}: not a CSV voltage sequence ({err})") from None
    rows = [r for r in rows if r and not r[0].lstrip().startswith("#")]
    if not rows:
        raise OptionError(f"{path}: empty voltage sequence")
    header = [h.strip() for h in rows[0]]
    expected = ["time [s]", "u1 [V]", "u2 [V]"][: len(header)]
    if len(header) < 2 or header != expected:
        raise OptionError(
            f"{path}: header must be 'time [s],u1 [V]' or 'time [s],u1 [V],u2 [V]', got "
            f"{shown(','.join(header))}"
        )
    times, volts = [], []
    for line, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise OptionError(f"{path}: row {line} has {len(row)} values, expected {len(header)}")
        try:
            numbers = [float(v) for v in row]
        except ValueError:
            raise OptionError(f"{path}: row {line} is not all numbers: {shown(row)}") from None
        times.append(numbers[0])
        volts.append(tuple(numbers[1:]))
    try:
        return SequenceProtocol(
            tuple(times),
            tuple(volts),
            duration_s,
            source=path.name,
            sha256=hashlib.sha256(raw).hexdigest(),
        )
    except OptionError as err:
        raise OptionError(f"{path}: {err}") from None
