"""The validated, in-memory form of one experiment, as every consumer (fitter, plots) sees it.

Timing convention (shared by the rig, the simulator and the fitter): sample k is taken at
``time_s[k]``; ``outputs[k]`` are the sensors read at that instant, and ``inputs[k]`` is the
voltage commanded right after reading them and held (zero-order hold) until sample k + 1.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hframe_id.parameters import ParameterSet


@dataclass(frozen=True)
class Recording:
    """One recorded experiment in SI units.

    Attributes
    ----------
    variant : model variant of the rig (``"one-axis"`` or an H-frame variant).
    sample_period_s : nominal sample period [s].
    time_s : (N,) sample times [s], starting at 0, strictly increasing.
    inputs : (N, n_u) commanded voltages [V], named by ``input_names`` (``u1``, ``u2``).
    outputs : (N, n_y) measured outputs in SI (``phi1``, ``phi2`` [rad]; ``x``, ``y`` [m]),
        NaN where the sensor gave no value.
    output_names : names of the output columns, model output names.
    valid : (N, n_y) True where the sample of that channel may be used (sensor valid, laser
        not holding its last value past its range).
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
    rig: dict[str, Any] = field(default_factory=dict)
    experiment: dict[str, Any] = field(default_factory=dict)
    truth: ParameterSet | None = None
    sequence_gaps: tuple[tuple[int, int], ...] = ()
    aborted: bool = False
    path: Path | None = None
    truncated: bool = False
    events: tuple[dict[str, Any], ...] = ()

    @property
    def n_samples(self) -> int:
        return int(self.time_s.shape[0])

    @property
    def duration_s(self) -> float:
        return float(self.time_s[-1] - self.time_s[0]) if self.n_samples else 0.0

    def name(self) -> str:
        return self.path.name if self.path else "<recording>"

    def to_dataframe(self) -> pd.DataFrame:
        """Samples as a DataFrame indexed by time [s]; columns carry units in their names."""
        units = {"phi1": "rad", "phi2": "rad", "x": "m", "y": "m"}
        data = {f"{n} [V]": self.inputs[:, i] for i, n in enumerate(self.input_names)}
        for i, n in enumerate(self.output_names):
            data[f"{n} [{units.get(n, '')}]"] = self.outputs[:, i]
            data[f"{n} valid"] = self.valid[:, i]
        return pd.DataFrame(data, index=pd.Index(self.time_s, name="time [s]"))
