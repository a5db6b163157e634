"""A recording replayed through a model: measured and simulated outputs on the model's channels.

The recording is read on the model's channels as the fitter reads it (``channels``: its
``hframe_id.fitting.dataset.Dataset``). Inputs are the voltages the plant saw: the commanded
ones through the rig's DAC; the amplifier gains g_i are parameters of the model and act
inside it. The simulation starts at rest at the first measured positions, as the
fitter's first node does for a record with a pre-roll, with the belts unstretched: the
coordinates are the belt-free (rigid) motion that best fits the first sample's valid
measurements, weighted by the sensors' noise (so the encoders place the motors, and the cart,
bridge and any unmeasured idler follow), averaged over the first ``REST_SAMPLES`` where the
record shows rest there; every velocity is zero. The fitter starts such a record from the
state (``FitOptions.initial_state``; ``fitting.rest_state``: its stages estimate the belt-free
position, its last solve takes this one), so that a fit's residuals are what this replay of
its parameter file shows. A coordinate measured only through its rate (a tachometer) starts at 0
with the measured rate as its velocity; outputs are the model's output map
(``Model.output_map``) of the simulated states under the recording's inputs, whatever they
measure (positions, speeds, a motor current).

A sensor that reports its sample d samples late (``--latency`` of the fit,
``FitOptions.latency_samples``) is compared as the fitter compares it: its channel advanced by
d samples (``Dataset.delayed``), its last d samples not counted. A fit's parameter file keeps
the latencies it was fitted with (``provenance.fit_options.latency_samples``:
``sensor_latency``), so that ``validate`` replays the file as the fit scored it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from hframe_id.errors import OptionError, ParameterFileError
from hframe_id.fitting.dataset import Dataset
from hframe_id.fitting.link_options import checked_latency
from hframe_id.fitting.rest_state import rest_state
from hframe_id.models import Model, build_model
from hframe_id.parameters import ParameterSet
from hframe_id.recordings.recording import Recording
from hframe_id.simulation.open_loop import default_substeps, outputs_of, simulate


def sensor_latency(params: ParameterSet) -> dict[str, int]:
    """The sensors' latencies [samples] per output that the fit which wrote ``params``
    compared its channels with (``provenance.fit_options.latency_samples``); empty for a
    file without them. ``ParameterFileError`` naming the file, field and value for one that
    is not a whole number of samples in 0..100 (the fit's own range)."""
    options = params.provenance.get("fit_options")
    latency = options.get("latency_samples") if isinstance(options, Mapping) else None
    if latency is None:
        return {}
    try:
        return checked_latency(latency)
    except OptionError as error:
        raise ParameterFileError(f"{params.where()}: provenance.fit_options.{error}") from None


def channels(
    model: Model, recording: Recording, latency: Mapping[str, int] | None = None
) -> Dataset:
    """The recording on ``model``'s channels (``Dataset.from_recording``; checked by
    ``checks.check_signals``), each channel named in ``latency`` advanced by its latency
    [samples] (``Dataset.delayed``)."""
    return Dataset.from_recording(model, recording).delayed(latency or {})


def simulate_channels(
    params: ParameterSet,
    recording: Recording,
    x0: np.ndarray | None = None,
    latency: Mapping[str, int] | None = None,
) -> tuple[Dataset, np.ndarray]:
    """The recording's channels for ``params``'s model (advanced by the sensors' ``latency``
    [samples], ``channels``) and their open-loop simulation, from ``x0`` (default:
    ``rest_state``).

    Returns
    -------
    data : the measured channels (``Dataset``).
    simulated : (N, n_y) simulated outputs [SI] at the sample instants, from rest at the
        first measured positions under the recording's DAC voltages (zero-order hold).
    """
    model = build_model(params.variant)
    p = model.parameter_vector(params.values)
    data = channels(model, recording, latency)
    # the substeps first: values too stiff to simulate are refused by name there, before
    # the rest state's least squares fail on them without saying which (an r of 1e300 m)
    n_substeps = default_substeps(model, p, data.sample_period_s)
    start = rest_state(model, p, data) if x0 is None else x0
    states = simulate(model, p, data.inputs, data.sample_period_s, x0=start, n_substeps=n_substeps)
    states = states[:-1]
    return data, outputs_of(model, states, data.inputs, p)
