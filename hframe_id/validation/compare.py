"""Validation of parameter sets on recordings: per recording, parameter set and channel, the
simulation fit, the k-step-ahead prediction fit and the residual tests (``resid``); per
recording and parameter set, the scores the literature uses: the open-loop RMSE after an
initialisation window, the inverse-model force error and, with a declared controller, the
closed-loop relative errors."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hframe_id.control.declaration import ControllerDeclaration
from hframe_id.control.loop import check_fits
from hframe_id.errors import OptionError
from hframe_id.fitting.dataset import Dataset
from hframe_id.models import build_model
from hframe_id.parameters import ParameterSet
from hframe_id.recordings.recording import Recording
from hframe_id.simulation.friction import FrictionOptions
from hframe_id.validation.checks import check_inputs
from hframe_id.validation.closed_loop import ClosedLoopScore, closed_loop_score
from hframe_id.validation.inverse_model import InverseModelScore, inverse_model_score
from hframe_id.validation.metrics import fit_percent
from hframe_id.validation.open_loop_rmse import DEFAULT_INIT_SAMPLES, open_loop_rmse
from hframe_id.validation.prediction import DEFAULT_HORIZON, DEFAULT_WINDOW, predict_ahead
from hframe_id.validation.replay import sensor_latency, simulate_channels
from hframe_id.validation.residuals import (
    DEFAULT_MAX_LAG,
    CorrelationTest,
    autocorrelation,
    cross_correlation,
)


@dataclass(frozen=True)
class ValidationOptions:
    """What ``validate`` computes.

    Attributes
    ----------
    horizon : k of the k-step-ahead prediction [samples], >= 1; 0 skips the prediction.
    window : past samples m for the prediction's state estimate, >= 1.
    max_lag : largest lag L of the residual correlations [samples], >= 1.
    init_samples : samples that initialise the open-loop RMSE (not counted in it), >= 1.
    controller : the controller the rig ran under; given, every parameter set is also run in
        closed loop with it (``closed_loop``).
    friction : Coulomb law of the closed loop and the inverse model: ``"sign"`` (the
        benchmarks' discontinuous law, their published numbers), ``"smooth"`` (the model's
        tanh, as fitted) or ``"stick-slip"`` (``hframe_id.simulation.friction``).
    """

    horizon: int = DEFAULT_HORIZON
    window: int = DEFAULT_WINDOW
    max_lag: int = DEFAULT_MAX_LAG
    init_samples: int = DEFAULT_INIT_SAMPLES
    controller: ControllerDeclaration | None = None
    friction: str = "sign"

    def __post_init__(self) -> None:
        for name, low in (("horizon", 0), ("window", 1), ("max_lag", 1), ("init_samples", 1)):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < low:
                raise OptionError(f"{name} must be an integer >= {low} samples, got {value!r}")
        if self.controller is not None and not isinstance(self.controller, ControllerDeclaration):
            raise OptionError(
                f"controller must be a ControllerDeclaration, got {self.controller!r}"
            )
        FrictionOptions(self.friction)


@dataclass(frozen=True)
class ChannelResult:
    """One output channel of one recording under one parameter set.

    Attributes
    ----------
    name, unit : channel (``phi1`` [rad], ``x`` [m], ``omega`` [rad/s], ...).
    valid_samples : samples used.
    simulation_fit_percent, prediction_fit_percent : fit [%] (NaN if undefined; prediction
        NaN when skipped).
    residual_rms : rms of the simulation residual over the valid samples [unit].
    autocorrelation : whiteness test of the simulation residual.
    cross_correlation : independence test against each input, by input name.
    """

    name: str
    unit: str
    valid_samples: int
    simulation_fit_percent: float
    prediction_fit_percent: float
    residual_rms: float
    autocorrelation: CorrelationTest
    cross_correlation: dict[str, CorrelationTest]

    @property
    def independent(self) -> bool | None:
        """Residual independent of every input (None if no test was defined: constant inputs)."""
        return _all_defined(t.passes for t in self.cross_correlation.values())

    @property
    def passes(self) -> bool | None:
        """Residual white and independent of every input (None if no test was defined)."""
        return _all_defined((self.autocorrelation.passes, self.independent))


def _all_defined(verdicts) -> bool | None:
    """All defined verdicts true; None if none is defined."""
    known = [v for v in verdicts if v is not None]
    return all(known) if known else None


@dataclass(frozen=True)
class RunResult:
    """One recording under one parameter set, with the signals for plots.

    Attributes
    ----------
    label : the parameter set's label (its file name).
    params : the parameter set.
    data : the recording's channels (measured, valid, inputs).
    simulated, predicted : (N, n_y) simulated and k-step-ahead outputs [SI].
    channels : per-channel results, in the model's output order.
    open_loop_rmse : by channel, the open-loop RMSE after ``init_samples`` [SI unit].
    inverse_model : the inverse-model (IDIM) force error.
    closed_loop : the closed-loop relative errors, None without a controller.
    """

    label: str
    params: ParameterSet
    data: Dataset
    simulated: np.ndarray
    predicted: np.ndarray
    channels: tuple[ChannelResult, ...]
    open_loop_rmse: dict[str, float]
    inverse_model: InverseModelScore
    closed_loop: ClosedLoopScore | None


@dataclass(frozen=True)
class RecordingResult:
    """Every parameter set on one recording."""

    recording: Recording
    runs: tuple[RunResult, ...]


@dataclass(frozen=True)
class ValidationResult:
    """``validate``'s result: options, the labelled parameter sets, one entry per recording,
    and per set the sensors' latencies [samples] its channels were compared with
    (``replay.sensor_latency``)."""

    options: ValidationOptions
    labels: tuple[str, ...]
    parameter_sets: tuple[ParameterSet, ...]
    recordings: tuple[RecordingResult, ...]
    latencies: tuple[dict[str, int], ...]


def label_of(params: ParameterSet) -> str:
    """The name a parameter set is shown under: its file name, else its title."""
    return params.path.name if params.path else params.title


def labels_of(parameter_sets: Sequence[ParameterSet]) -> tuple[str, ...]:
    """Each set's ``label_of``, made unique by position (``#2``) where two share one."""
    labels: list[str] = []
    for i, params in enumerate(parameter_sets):
        label = label_of(params)
        labels.append(label if label not in labels else f"{label} #{i + 1}")
    return tuple(labels)


def _channel(run_data: Dataset, j: int, simulated, predicted, options) -> ChannelResult:
    valid = run_data.valid[:, j]
    measured = run_data.measured[:, j]
    residual = np.where(valid, measured - simulated[:, j], 0.0)
    n = int(valid.sum())
    return ChannelResult(
        name=run_data.names[j],
        unit=run_data.units[j],
        valid_samples=n,
        simulation_fit_percent=fit_percent(measured, simulated[:, j], valid),
        prediction_fit_percent=fit_percent(measured, predicted[:, j], valid),
        residual_rms=float(np.sqrt(residual @ residual / n)) if n else float("nan"),
        autocorrelation=autocorrelation(residual, valid, options.max_lag),
        cross_correlation={
            name: cross_correlation(residual, valid, run_data.inputs[:, i], options.max_lag)
            for i, name in enumerate(run_data.input_names)
        },
    )


def validate_one(
    params: ParameterSet,
    recording: Recording,
    options: ValidationOptions,
    label: str,
    latency: dict[str, int] | None = None,
) -> RunResult:
    """One parameter set on one recording (checked beforehand by ``checks.check_inputs``),
    its channels advanced by the sensors' ``latency`` [samples] (``replay.channels``)."""
    data, simulated = simulate_channels(params, recording, latency=latency)
    if options.horizon:
        predicted = predict_ahead(params, data, options.horizon, options.window)
    else:
        predicted = np.full(simulated.shape, np.nan)
    channels = tuple(
        _channel(data, j, simulated, predicted, options) for j in range(len(data.names))
    )
    friction = FrictionOptions(options.friction)
    closed_loop = None
    if options.controller is not None:
        closed_loop = closed_loop_score(params, recording, options.controller, friction)
    return RunResult(
        label,
        params,
        data,
        simulated,
        predicted,
        channels,
        open_loop_rmse(params, recording, options.init_samples, latency),
        inverse_model_score(params, data, friction),
        closed_loop,
    )


def validate(
    parameter_sets: Sequence[ParameterSet],
    recordings: Sequence[Recording],
    options: ValidationOptions | None = None,
) -> ValidationResult:
    """Judge parameter sets on recordings as MATLAB's ``compare`` and ``resid`` do.

    Parameters
    ----------
    parameter_sets : the sets to compare, the one under test first (e.g. a fit, then the
        thesis's table); labelled by file name (made unique by position if two share one).
    recordings : held-out recordings of one rig.
    options : horizon, window, lags (default ``ValidationOptions()``).

    A fit's file is replayed with the sensors' latencies it was fitted with
    (``replay.sensor_latency``), as the fit scored it.

    Raises
    ------
    OptionError : before any simulation, if a set's model cannot produce a recording's
        channels from its inputs, or the recordings come from different rigs.
    ParameterFileError : before any simulation, a file's latencies that are not whole
        samples in 0..100.
    ControllerError : before any simulation, if the controller does not drive a set's model
        or reads a signal a recording lacks.
    """
    options = options or ValidationOptions()
    parameter_sets = tuple(parameter_sets)
    if not parameter_sets:
        raise OptionError("no parameter sets to validate")
    check_inputs(parameter_sets, recordings)
    latencies = tuple(sensor_latency(params) for params in parameter_sets)
    if options.controller is not None:
        for params in parameter_sets:
            model = build_model(params.variant)
            for rec in recordings:
                check_fits(options.controller, model, rec)
                options.controller.sample_period(rec)
    labels = labels_of(parameter_sets)
    results = tuple(
        RecordingResult(
            rec,
            tuple(
                validate_one(params, rec, options, label, latency)
                for params, label, latency in zip(parameter_sets, labels, latencies, strict=True)
            ),
        )
        for rec in recordings
    )
    return ValidationResult(options, labels, parameter_sets, results, latencies)
