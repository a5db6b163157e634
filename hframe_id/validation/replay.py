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
same velocities and unstretched belts (``FitOptions.initial_state``; its belt-free position
is estimated), so that a fit's residuals are what this replay of its
parameter file shows. A coordinate measured only through its rate (a tachometer) starts at 0
with the measured rate as its velocity; outputs are the model's output map
(``Model.output_map``) of the simulated states under the recording's inputs, whatever they
measure (positions, speeds, a motor current).
"""

from __future__ import annotations

import numpy as np

from hframe_id.fitting.dataset import REST_SAMPLES, Dataset, state_outputs
from hframe_id.fitting.problem import output_matrix, rigid_modes
from hframe_id.models import Model, build_model
from hframe_id.parameters import ParameterSet
from hframe_id.recordings.recording import Recording
from hframe_id.simulation.open_loop import outputs_of, simulate


def channels(model: Model, recording: Recording) -> Dataset:
    """The recording on ``model``'s channels (``Dataset.from_recording``; checked by
    ``checks.check_signals``)."""
    return Dataset.from_recording(model, recording)


def measured_positions(model: Model, p: np.ndarray, data: Dataset) -> np.ndarray:
    """(N, n_q) belt-free coordinates [m or rad] at every sample from the measurements alone.

    Per sample, the amplitudes of the rigid (belt-free) motions are fitted to the valid
    position outputs (coordinates), weighted by the sensor noise; the belts are taken
    unstretched; outputs of other kinds (rates, currents) place nothing. Not the raw
    measurements: a laser's noise (5 um) taken as a belt stretch would move a motor by
    5 um / r ~ 2.6e-4 rad, 50 encoder steps, once released. A sample with fewer valid outputs
    than rigid modes keeps the previous sample's positions (zero at the start).
    """
    nq = model.n_states // 2
    c = output_matrix(model)[:, :nq]
    modes = rigid_modes(model, p)
    index = state_outputs(model)
    placing = data.valid & ((index >= 0) & (index < nq))[None, :]
    y = np.where(placing, data.measured, 0.0)
    positions = np.zeros((y.shape[0], nq))
    enough = np.count_nonzero(placing, axis=1) >= modes.shape[1]
    patterns, group = np.unique(placing, axis=0, return_inverse=True)
    for g, used in enumerate(patterns):
        ks = np.flatnonzero((group.ravel() == g) & enough)
        if ks.size:
            # Samples with the same valid channels share the design: one solve for all.
            w = used / data.noise_std
            coef, *_ = np.linalg.lstsq((c @ modes) * w[:, None], (y[ks] * w).T, rcond=None)
            positions[ks] = (modes @ coef).T
    for k in np.flatnonzero(~enough):
        positions[k] = positions[k - 1] if k else 0.0
    return positions


def measured_rates(model: Model, data: Dataset) -> np.ndarray:
    """(N, n_q) the coordinates' rates the channels measure (a tachometer) [SI], NaN where no
    valid sample of a rate channel gives one."""
    nq = model.n_states // 2
    rates = np.full((data.measured.shape[0], nq), np.nan)
    index = state_outputs(model)
    for j in np.flatnonzero(index >= nq):
        rates[data.valid[:, j], index[j] - nq] = data.measured[data.valid[:, j], j]
    return rates


def rest_state(model: Model, p: np.ndarray, data: Dataset) -> np.ndarray:
    """(n_x,) state at rest (velocities zero, belts unstretched) at the measured positions:
    the mean over the first ``REST_SAMPLES`` where the record shows rest there
    (``Dataset.at_rest``; a laser's noise averaged down by sqrt(10)), else the first sample's. A
    rate a channel measures (a tachometer, ``measured_rates``) starts at its measurement,
    averaged the same way (zero within its noise at rest)."""
    rest = data.at_rest
    nq = model.n_states // 2
    positions = measured_positions(model, p, data)
    x0 = np.zeros(model.n_states)
    x0[:nq] = positions[:REST_SAMPLES].mean(axis=0) if rest else positions[0]
    rates = measured_rates(model, data)[: REST_SAMPLES if rest else 1]
    seen = np.isfinite(rates).any(axis=0)
    x0[nq:][seen] = np.nanmean(rates[:, seen], axis=0)
    return x0


def simulate_channels(
    params: ParameterSet, recording: Recording, x0: np.ndarray | None = None
) -> tuple[Dataset, np.ndarray]:
    """The recording's channels for ``params``'s model and their open-loop simulation, from
    ``x0`` (default: ``rest_state``).

    Returns
    -------
    data : the measured channels (``Dataset``).
    simulated : (N, n_y) simulated outputs [SI] at the sample instants, from rest at the
        first measured positions under the recording's DAC voltages (zero-order hold).
    """
    model = build_model(params.variant)
    p = model.parameter_vector(params.values)
    data = channels(model, recording)
    start = rest_state(model, p, data) if x0 is None else x0
    states = simulate(model, p, data.inputs, data.sample_period_s, x0=start)[:-1]
    return data, outputs_of(model, states, data.inputs, p)
