"""The open-loop RMSE of the nonlinear system identification benchmarks, after a stated
initialisation window.

The benchmarks' figure of merit (nonlinearbenchmark.org; for EMPS, Forgione & Piga 2021,
"Continuous-time system identification with neural networks", RMSE in mm from the voltage to
the position): the model is simulated open loop under the recorded inputs over the whole
record, the first n samples may serve only to initialise it, and

    RMSE = sqrt(mean((y_k - y_sim,k)^2)) over k = n .. N - 1   [the output's unit]

per output channel. Here the first n samples (``--init-samples``, default 20) initialise it by
estimating the state at the first sample from them alone (output-error least squares, the
k-step prediction's estimator: ``prediction.initial_state``). The simulation is the model's own
(its smoothed Coulomb law, as the other open-loop figures of ``validate``). A prediction error
in the output's unit, not a fit % that rounds to 100.00 for every good model.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from hframe_id.parameters import ParameterSet
from hframe_id.recordings.recording import Recording
from hframe_id.validation.prediction import initial_state
from hframe_id.validation.replay import channels, simulate_channels

#: Initialisation samples of the benchmarks' open-loop RMSE (Forgione & Piga 2021 on EMPS).
DEFAULT_INIT_SAMPLES = 20


def open_loop_rmse(
    params: ParameterSet,
    recording: Recording,
    init_samples: int = DEFAULT_INIT_SAMPLES,
    latency: Mapping[str, int] | None = None,
) -> dict[str, float]:
    """RMSE of each output channel after ``init_samples`` [the channel's SI unit], the
    channels advanced by the sensors' ``latency`` [samples] (``replay.channels``); NaN for a
    channel without a valid sample after them."""
    from hframe_id.models import build_model

    data = channels(build_model(params.variant), recording, latency)
    window = min(init_samples, data.measured.shape[0] - 1)
    x0 = initial_state(params, data, window)
    _, simulated = simulate_channels(params, recording, x0, latency)
    rmse = {}
    for j, name in enumerate(data.names):
        valid = data.valid[init_samples:, j]
        residual = (data.measured[init_samples:, j] - simulated[init_samples:, j])[valid]
        rmse[name] = float(np.sqrt(np.mean(residual**2))) if residual.size else float("nan")
    return rmse
