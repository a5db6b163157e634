"""How much larger than predicted a fit's errors come out on this rig: the misfit factor.

On a plant the model does not match, the fit's residuals are model error, correlated over
hundreds of samples; its ``robust`` standard errors (HAC over those residuals) are then many
times the textbook ones the prediction gives (measured 20-200 x on a realistic plant's six
steps, docs/studies/2026-11-26-design.md). The recordings a parameter file was fitted to
measure that factor: the file's reported standard error of each free parameter over the one
``information`` predicts for the same recordings at the file's values,

    factor = max(1, median_i  std_reported_i / std_predicted_i),

applied to every prediction on the same rig (the same model error is assumed to follow the
model into the next experiment; the median keeps a parameter the recordings barely
determine from deciding it).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from hframe_id.design.information import experiment_information
from hframe_id.errors import OptionError
from hframe_id.fitting.options import FitOptions
from hframe_id.parameters import ParameterSet
from hframe_id.recordings.sensors import SensorModel


def reported_std_error(params: ParameterSet, names: Sequence[str]) -> np.ndarray:
    """(n,) the standard errors [SI] the file's ``uncertainty`` reports for ``names`` (NaN
    for a name it does not list)."""
    listed = params.uncertainty.get("parameters", {})
    by_name = {str(key).split(" [")[0]: entry for key, entry in listed.items()}
    values = []
    for name in names:
        std = (by_name.get(name) or {}).get("std_error")
        values.append(float(std) if isinstance(std, int | float) else np.nan)
    return np.array(values)


def misfit_factor(
    params: ParameterSet,
    tables: Sequence[np.ndarray],
    fit_options: FitOptions,
    sensors: SensorModel,
    sample_period_s: float,
) -> float:
    """The misfit factor (module docstring) of ``params``, fitted to recordings of the inputs
    ``tables`` (each (N, n_u) [V]); ``OptionError`` if the file reports no standard errors
    to compare with."""
    info = experiment_information(params, list(tables), fit_options, sensors, sample_period_s)
    predicted = info.predicted_relative_std() * np.abs(info.slopes)
    reported = reported_std_error(params, info.names)
    usable = np.isfinite(reported) & np.isfinite(predicted) & (predicted > 0) & (reported > 0)
    if not usable.any():
        raise OptionError(
            f"--calibrate: {params.where()} reports no standard errors of the free parameters "
            "to compare with (give the file of the fit of these recordings)"
        )
    return max(1.0, float(np.median(reported[usable] / predicted[usable])))
