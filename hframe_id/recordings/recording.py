"""The validated, in-memory form of one experiment, as every consumer (fitter, plots) sees it.

Timing convention (shared by the rig, the simulator and the fitter): sample k is taken at
``time_s[k]``; ``outputs[k]`` are the sensors read at that instant, and ``inputs[k]`` is the
input (voltage, force, ...) commanded right after reading them and held (zero-order hold)
until sample k + 1.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hframe_id.errors import ModelError
from hframe_id.parameters import ParameterSet
from hframe_id.recordings import log_format as fmt
from hframe_id.recordings.channels import HFRAME_UNITS

if TYPE_CHECKING:  # pandas costs 0.5-1 s to import; only to_dataframe needs it
    import pandas as pd


@dataclass(frozen=True)
class Recording:
    """One recorded experiment in SI units.

    Attributes
    ----------
    variant : model variant of the rig (``"one-axis"``, an H-frame variant, or any model
        name; the model that consumes the recording checks that it fits).
    sample_period_s : nominal sample period [s].
    time_s : (N,) sample times [s], starting at 0, strictly increasing.
    inputs : (N, n_u) commanded inputs in SI, named by ``input_names`` (H-frame rig: ``u1``,
        ``u2`` [V]).
    outputs : (N, n_y) measured outputs in SI (H-frame rig: ``phi1``, ``phi2`` [rad]; ``x``,
        ``y`` [m]), NaN where the sensor gave no value.
    output_names : names of the output columns, model output names.
    valid : (N, n_y) True where the sample of that channel may be used (sensor valid, laser
        not holding its last value past its range).
    units : SI unit of each channel (input, output, signal) by name (``"V"``, ``"m"``, ...);
        a name it lacks has the H-frame rig's unit (u1, u2 [V]; phi1, phi2 [rad]; x, y [m]).
        ``input_units``, ``output_units`` and ``signal_units`` list them per column.
    signals : (N, n_s) extra recorded signals in SI, neither model inputs nor outputs (a
        reference trajectory, say), NaN where there is no value; default: none (N, 0).
    signal_names : their names.
    rig, experiment : the MCAP metadata records (strings parsed to numbers where numeric).
    truth : the plant's parameter set if the recording carries it (sim rig), else None.
    sequence_gaps : (position, missing count) of each gap in the sequence numbers; position is
        the index of the first sample after the gap.
    aborted : True if the run was aborted (limit switch, link fault, user).
    path : the file it was read from, if any.
    truncated : True if the file was unfinished (writer killed) and salvaged.
    events : the run's events (``/rig/event`` messages: kind, reason, sequence, device time).
    """

    variant: str
    sample_period_s: float
    time_s: np.ndarray
    inputs: np.ndarray
    input_names: tuple[str, ...]
    outputs: np.ndarray
    output_names: tuple[str, ...]
    valid: np.ndarray
    units: dict[str, str] = field(default_factory=dict)
    signals: np.ndarray | None = None
    signal_names: tuple[str, ...] = ()
    rig: dict[str, Any] = field(default_factory=dict)
    experiment: dict[str, Any] = field(default_factory=dict)
    truth: ParameterSet | None = None
    sequence_gaps: tuple[tuple[int, int], ...] = ()
    aborted: bool = False
    path: Path | None = None
    truncated: bool = False
    events: tuple[dict[str, Any], ...] = ()

    def __post_init__(self) -> None:
        names = self.input_names + self.output_names + self.signal_names
        unknown = [n for n in names if n not in self.units and n not in HFRAME_UNITS]
        if unknown:
            raise ModelError(
                f"Recording: no unit for {', '.join(unknown)}; give units={{name: SI unit}} (only "
                "the H-frame rig's u1, u2, phi1, phi2, x, y have default units)"
            )
        n = self.time_s.shape[0]
        if not self.signal_names:  # an empty block fits any length (also after replace())
            object.__setattr__(self, "signals", np.empty((n, 0)))
        elif self.signals is None or self.signals.shape != (n, len(self.signal_names)):
            shape = None if self.signals is None else self.signals.shape
            raise ModelError(
                f"Recording: signals must be ({n}, {len(self.signal_names)}) for "
                f"{', '.join(self.signal_names)}, got {shape}"
            )

    def _units(self, names: tuple[str, ...]) -> tuple[str, ...]:
        return tuple(self.units.get(n) or HFRAME_UNITS[n] for n in names)

    @property
    def input_units(self) -> tuple[str, ...]:
        """SI unit of each input column."""
        return self._units(self.input_names)

    @property
    def output_units(self) -> tuple[str, ...]:
        """SI unit of each output column."""
        return self._units(self.output_names)

    @property
    def signal_units(self) -> tuple[str, ...]:
        """SI unit of each extra signal column."""
        return self._units(self.signal_names)

    @property
    def n_samples(self) -> int:
        """Number of samples."""
        return int(self.time_s.shape[0])

    @property
    def duration_s(self) -> float:
        """Time from the first to the last sample [s] (0 for an empty recording)."""
        return float(self.time_s[-1] - self.time_s[0]) if self.n_samples else 0.0

    def name(self) -> str:
        """The file name of the recording, or ``<recording>`` if it was not read from a file."""
        return self.path.name if self.path else "<recording>"

    def declared_noise_std(self, output: str) -> float | str | None:
        """The sensor noise std of ``output`` the rig metadata declare (``noise_std_<output>``):
        a float [the output's SI unit], ``"estimate"`` (to be estimated from the data), or
        None when not declared."""
        if output not in self.output_names:
            raise ModelError(
                f"{self.name()}: no output {output!r} (outputs: {', '.join(self.output_names)})"
            )
        value = self.rig.get(fmt.NOISE_STD_PREFIX + output)
        if value is None:
            return None
        try:
            return fmt.parse_noise_std(value)
        except ValueError as err:
            raise ModelError(f"{self.name()}: rig.{fmt.NOISE_STD_PREFIX}{output} {err}") from None

    def to_dataframe(self) -> pd.DataFrame:
        """Samples as a DataFrame indexed by time [s]; columns carry units in their names
        (inputs, then each output with its validity, then the extra signals)."""
        import pandas as pd

        data = {
            f"{n} [{u}]": self.inputs[:, i]
            for i, (n, u) in enumerate(zip(self.input_names, self.input_units, strict=True))
        }
        for i, (n, u) in enumerate(zip(self.output_names, self.output_units, strict=True)):
            data[f"{n} [{u}]"] = self.outputs[:, i]
            data[f"{n} valid"] = self.valid[:, i]
        for i, (n, u) in enumerate(zip(self.signal_names, self.signal_units, strict=True)):
            data[f"{n} [{u}]"] = self.signals[:, i]
        return pd.DataFrame(data, index=pd.Index(self.time_s, name="time [s]"))
