"""Leave-one-recording-out cross-validation of a fit: each recording is predicted by
parameters fitted on the others.

A fit judged on its own data always looks good; one judged on a recording it did not see
shows whether the parameters generalise (another amplitude, the other axis). The spread of
the parameters across folds shows how much each depends on which experiments were used.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from hframe_id.errors import FitError
from hframe_id.fitting import FitOptions, fit_recordings
from hframe_id.models import build_model
from hframe_id.parameters import ParameterSet
from hframe_id.recordings.recording import Recording
from hframe_id.validation.checks import check_inputs
from hframe_id.validation.metrics import fit_percent
from hframe_id.validation.replay import simulate_channels


@dataclass(frozen=True)
class Fold:
    """One fold: the recording held out and what the others' fit made of it.

    Attributes
    ----------
    held_out : name of the held-out recording.
    success, message : the fold's fit outcome.
    fit_percent : simulation fit [%] of the held-out recording per output channel.
    parameters : the fold's fitted values of the free parameters (SI).
    """

    held_out: str
    success: bool
    message: str
    fit_percent: dict[str, float]
    parameters: dict[str, float]


@dataclass(frozen=True)
class Spread:
    """One free parameter across the successful folds (SI; ``unit`` names it).

    ``relative_std_percent`` = 100 std / |mean| (NaN with fewer than two folds).
    ``jackknife_std``: the experiment-level (delete-one) jackknife standard error of the
    all-recordings estimate, sqrt((n - 1) / n sum (p_i - mean)^2) = (n - 1) / sqrt(n) std. It
    needs no noise model and holds model error that differs between experiments, which the
    fit's own intervals (noise only) do not.
    """

    name: str
    unit: str
    mean: float
    std: float
    minimum: float
    maximum: float
    relative_std_percent: float
    jackknife_std: float


@dataclass(frozen=True)
class LeaveOneOutTable:
    """Folds in recording order, the channels, and the parameters' spread across folds."""

    channels: tuple[str, ...]
    folds: tuple[Fold, ...]
    spread: tuple[Spread, ...]

    def markdown(self) -> str:
        """Two markdown tables: fit [%] per held-out recording, parameter spread."""
        head = "| held out | fit | " + " | ".join(f"{c} fit [%]" for c in self.channels) + " |"
        lines = [head, "|" + " --- |" * (2 + len(self.channels))]
        for fold in self.folds:
            cells = " | ".join(f"{fold.fit_percent[c]:.2f}" for c in self.channels)
            status = "converged" if fold.success else f"FAILED ({fold.message})"
            lines.append(f"| {fold.held_out} | {status} | {cells} |")
        lines += [
            "",
            "| parameter | mean | std | min | max | std / mean [%] | jackknife std |",
            "| --- | --- | --- | --- | --- | --- | --- |",
        ]
        for s in self.spread:
            lines.append(
                f"| {s.name} [{s.unit}] | {s.mean:.6g} | {s.std:.3g} | {s.minimum:.6g} | "
                f"{s.maximum:.6g} | {s.relative_std_percent:.2f} | {s.jackknife_std:.3g} |"
            )
        return "\n".join(lines)


def _spread(folds: Sequence[Fold], initial: ParameterSet) -> tuple[Spread, ...]:
    units = {spec.name: spec.unit for spec in build_model(initial.variant).parameters}
    good = [f for f in folds if f.success]
    names = list(folds[0].parameters) if folds else []
    rows = []
    for name in names:
        values = np.array([f.parameters[name] for f in good])
        if values.size == 0:
            continue
        mean = float(values.mean())
        std = float(values.std(ddof=1)) if values.size > 1 else math.nan
        rows.append(
            Spread(
                name=name,
                unit=units[name],
                mean=mean,
                std=std,
                minimum=float(values.min()),
                maximum=float(values.max()),
                relative_std_percent=100.0 * std / abs(mean) if mean else math.nan,
                jackknife_std=(values.size - 1) / math.sqrt(values.size) * std,
            )
        )
    return tuple(rows)


def leave_one_out(
    recordings: Sequence[Recording],
    initial: ParameterSet,
    options: FitOptions | None = None,
    progress: Callable[[int, int, str], None] | None = None,
) -> LeaveOneOutTable:
    """For each recording, fit on all the others and report its simulation fit per channel.

    Parameters
    ----------
    recordings : two or more recordings of one rig.
    initial : start of every fold's fit (and the model).
    options : the fit's options (``hframe_id.fitting.FitOptions``), the same for every fold.
    progress : called before each fold's fit with (fold number from 1, folds, held-out
        recording's name).

    Returns
    -------
    The folds (a failed fold is reported, its fit [%] computed with the parameters it ended
    at) and the free parameters' spread across the converged folds.

    Raises
    ------
    FitError : fewer than two recordings; ``OptionError``: recordings of different rigs or
        channels the model cannot produce (before any fit).
    """
    recordings = list(recordings)
    if len(recordings) < 2:
        raise FitError(f"leave-one-out needs at least two recordings, got {len(recordings)}")
    check_inputs([initial], recordings)
    folds = []
    for i, held in enumerate(recordings):
        if progress is not None:
            progress(i + 1, len(recordings), held.name())
        result = fit_recordings(recordings[:i] + recordings[i + 1 :], initial, options)
        latency = result.options.latency_samples
        data, simulated = simulate_channels(result.parameters, held, latency=latency)
        folds.append(
            Fold(
                held_out=held.name(),
                success=bool(result.success),
                message=result.message,
                fit_percent={
                    name: fit_percent(data.measured[:, j], simulated[:, j], data.valid[:, j])
                    for j, name in enumerate(data.names)
                },
                parameters={name: result.parameters.values[name] for name in result.free_names},
            )
        )
    channels = tuple(folds[0].fit_percent)
    return LeaveOneOutTable(channels, tuple(folds), _spread(folds, initial))
