"""Recordings made from a simulated plant in one batch (no pacing, no file): the quick path for
tests and benchmarks. It applies the same sensor models as the ``sim`` rig backend.
"""

from __future__ import annotations

import numpy as np

from hframe_id.models import build_model
from hframe_id.parameters import ParameterSet
from hframe_id.recordings.recording import Recording
from hframe_id.recordings.sensors import SensorModel, measure_batch
from hframe_id.simulation.open_loop import outputs_of, simulate


def simulate_recording(
    params: ParameterSet,
    voltages: np.ndarray,
    sample_period_s: float = 1e-3,
    sensors: SensorModel | None = None,
    seed: int = 0,
    n_substeps: int | None = None,
    experiment: dict | None = None,
) -> Recording:
    """Simulate an open-loop experiment and measure it with the rig's sensor models.

    Parameters
    ----------
    params : plant parameters (the truth, attached to the recording).
    voltages : (N, n_u) commanded voltages [V], one row per sample (ZOH).
    sample_period_s : sample period [s].
    sensors : sensor models (default: the thesis's rig).
    seed : seeds the encoder power-up phase and the laser noise.
    n_substeps : RK4 substeps (default: stable for these parameters, see integrators).
    """
    sensors = sensors or SensorModel()
    model = build_model(params.variant)
    commanded = np.atleast_2d(np.asarray(voltages, dtype=float))
    applied = sensors.dac(commanded)
    p = model.parameter_vector(params.values)
    states = simulate(model, p, applied, sample_period_s, n_substeps=n_substeps)[:-1]
    true_outputs = outputs_of(model, states, applied, p)
    names = tuple(s.name for s in model.outputs)
    # Same random draws, in the same order, as the sample-by-sample sim rig (see sensors.py).
    outputs, valid = measure_batch(sensors, names, true_outputs, np.random.default_rng(seed))
    time_s = np.arange(commanded.shape[0]) * sample_period_s
    return Recording(
        variant=params.variant,
        sample_period_s=sample_period_s,
        time_s=time_s,
        inputs=commanded,
        input_names=tuple(s.name for s in model.inputs),
        outputs=outputs,
        output_names=names,
        valid=valid,
        rig={"backend": "sim-batch", "seed": seed, **sensors.as_metadata()},
        experiment=dict(experiment or {}),
        truth=params,
    )
