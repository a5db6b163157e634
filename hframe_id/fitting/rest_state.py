"""Where a record at rest starts: the state ``validate`` replays it from, which the fitter's
last solve takes too (``fitting.replayed_rest``).

The coordinates are the belt-free (rigid) motion that best fits each sample's valid
position measurements, weighted by the sensors' noise (the encoders place the motors; the
cart, bridge and any unmeasured idler follow), averaged over the first ``REST_SAMPLES``
where the record shows rest; every velocity is zero, or a measured rate's (a tachometer).
"""

from __future__ import annotations

import numpy as np

from hframe_id.fitting.dataset import REST_SAMPLES, Dataset, state_outputs
from hframe_id.fitting.problem import output_matrix, rigid_modes
from hframe_id.models import Model


def measured_positions(
    model: Model, p: np.ndarray, data: Dataset, hold_missing: bool = True
) -> np.ndarray:
    """(N, n_q) belt-free coordinates [m or rad] at every sample from the measurements alone.

    Per sample, the amplitudes of the rigid (belt-free) motions are fitted to the valid
    position outputs (coordinates), weighted by the sensor noise; the belts are taken
    unstretched; outputs of other kinds (rates, currents) place nothing. Not the raw
    measurements: a laser's noise (5 um) taken as a belt stretch would move a motor by
    5 um / r ~ 2.6e-4 rad, 50 encoder steps, once released. A sample with fewer valid outputs
    than rigid modes keeps the previous sample's positions (zero at the start), or is NaN
    without ``hold_missing``.
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
        positions[k] = (positions[k - 1] if k else 0.0) if hold_missing else np.nan
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
    the mean over the samples that place the coordinates among the first ``REST_SAMPLES``
    where the record shows rest there (``Dataset.at_rest``; a laser's noise averaged down by
    up to sqrt(10)), else the first sample's; if none of those does, the first sample that
    does (zero if none). A rate a channel measures (a tachometer, ``measured_rates``) starts
    at its measurement, averaged the same way (zero within its noise at rest)."""
    rest = data.at_rest
    nq = model.n_states // 2
    positions = measured_positions(model, p, data, hold_missing=False)
    placed = np.isfinite(positions[:, 0])
    first = positions[: REST_SAMPLES if rest else 1]
    x0 = np.zeros(model.n_states)
    if placed[: first.shape[0]].any():
        x0[:nq] = np.nanmean(first, axis=0)
    elif placed.any():
        x0[:nq] = positions[np.argmax(placed)]
    rates = measured_rates(model, data)[: REST_SAMPLES if rest else 1]
    seen = np.isfinite(rates).any(axis=0)
    x0[nq:][seen] = np.nanmean(rates[:, seen], axis=0)
    return x0
