"""A recording prepared once on a model's channels: the first link of the fitting chain.

A ``Dataset`` is what fitting (each ``FitProblem.experiments`` entry), validation (the
replay, the prediction, the inverse model) and the benchmarks read of a recording: its
outputs in the model's order and SI units, NaN where a sensor flagged a sample invalid; the
voltages the plant saw (the commanded ones through the rig's DAC, ``applied_inputs``); each
channel's sensor noise std (``default_channel_std``: the weights 1 / std of a fit and of a
state estimate) and kind (a coordinate, a rate, another function of the state); and what is
known of the initial state: whether the record shows rest over its first ``REST_SAMPLES``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from hframe_id.errors import FitError
from hframe_id.fitting.experiment import applied_inputs, default_channel_std
from hframe_id.models import Model
from hframe_id.recordings.recording import Recording

#: A record starts at rest (``starts_at_rest``) unless some channel's velocity at its first
#: sample, fitted over its first ``REST_SAMPLES``, differs from zero by more than ``REST_Z``
#: of its standard errors (a two-sided test at 0.27 % per channel). 10 ms at 1 kHz: within
#: the pre-roll of every protocol here (>= 50 ms); the replay averages a record at rest over
#: them for its rest positions (``fitting.rest_state.rest_state``).
REST_Z = 3.0
REST_SAMPLES = 10


@dataclass(frozen=True)
class Dataset:
    """One recording on a model's channels (model order, SI).

    Attributes
    ----------
    name : the recording's name (``Recording.name``).
    recording : the recording itself (its rig metadata, time stamps, commanded inputs).
    names, units : output names and SI units (``phi1`` [rad], ``x`` [m], ``speed`` [rad/s]).
    kinds : per channel, ``"position"``, ``"rate"`` or ``"other"`` (``output_kinds``).
    measured : (N, n_y) measurements [SI], NaN where not valid.
    valid : (N, n_y) True where a sample may be used (``Recording.valid`` and finite).
    inputs : (N, n_u) voltages the plant saw [V] (after the DAC: ``applied_inputs``).
    input_names : names of the input columns (``u1``, ``u2``), the model's.
    noise_std : (n_y,) each channel's sensor noise std [SI] (``default_channel_std``: the
        rig's declaration, the model's ``Output``, the encoder step / sqrt(12), the laser's).
    sample_period_s : sample period [s].
    at_rest : True where the record is known to start at rest, its initial velocities
        zero: as its first ``REST_SAMPLES`` show (``shows_rest``), or as a fit's
        ``FitOptions.initial_state`` declares.
    """

    name: str
    recording: Recording
    names: tuple[str, ...]
    units: tuple[str, ...]
    kinds: tuple[str, ...]
    measured: np.ndarray
    valid: np.ndarray
    inputs: np.ndarray
    input_names: tuple[str, ...]
    noise_std: np.ndarray
    sample_period_s: float
    at_rest: bool

    @classmethod
    def from_recording(cls, model: Model, recording: Recording) -> Dataset:
        """The ``recording`` on ``model``'s inputs and outputs.

        Raises ``FitError`` for inputs other than the model's (names and order), an output of
        the model the recording lacks, non-finite applied inputs, or a channel whose noise
        neither the rig metadata nor the model declare (``default_channel_std``).
        """
        where = recording.name()
        inputs = applied_inputs(recording)
        input_names = tuple(s.name for s in model.inputs)
        if tuple(recording.input_names) != input_names:
            raise FitError(
                f"{where}: inputs {list(recording.input_names)} do not match model "
                f"{model.variant} inputs {list(input_names)}"
            )
        names = tuple(s.name for s in model.outputs)
        for name in names:
            if name not in recording.output_names:
                raise FitError(
                    f"{where}: no output {name!r} (has {list(recording.output_names)}) for "
                    f"model {model.variant}"
                )
        if not np.all(np.isfinite(inputs)):
            raise FitError(f"{where}: inputs contain non-finite values")
        columns = [list(recording.output_names).index(name) for name in names]
        measured = np.asarray(recording.outputs, dtype=float)[:, columns]
        valid = np.asarray(recording.valid, dtype=bool)[:, columns] & np.isfinite(measured)
        measured = np.where(valid, measured, np.nan)
        noise_std = np.array([default_channel_std(recording, name, model) for name in names])
        kinds = output_kinds(model)
        dt = float(recording.sample_period_s)
        return cls(
            name=where,
            recording=recording,
            names=names,
            units=tuple(s.unit for s in model.outputs),
            kinds=kinds,
            measured=measured,
            valid=valid,
            inputs=inputs,
            input_names=input_names,
            noise_std=noise_std,
            sample_period_s=dt,
            at_rest=starts_at_rest(measured, valid, noise_std, REST_SAMPLES, dt, kinds),
        )

    @property
    def n_samples(self) -> int:
        """Samples N in the record."""
        return int(self.inputs.shape[0])

    def shows_rest(self, noise_std: np.ndarray | None = None) -> bool:
        """Whether the channels show rest over the first ``REST_SAMPLES`` (``starts_at_rest``)
        with sensor noise ``noise_std`` [SI] (default: the dataset's own ``noise_std``)."""
        return starts_at_rest(
            self.measured,
            self.valid,
            self.noise_std if noise_std is None else noise_std,
            REST_SAMPLES,
            self.sample_period_s,
            self.kinds,
        )

    @property
    def excites(self) -> bool:
        """Whether the record can tell anything of the model's parameters: some input the
        plant saw changes value over it (compared exactly: a protocol holds its voltage
        sample after sample), or the plant does not stay at rest (``starts_at_rest`` over
        the whole record: a trend of some channel beyond ``REST_Z`` standard errors of its
        sensor noise, the test that decides a fit's initial velocities). Constant inputs and
        a plant at rest throughout: every parameter value simulates the same record."""
        if np.any(self.inputs != self.inputs[:1]):
            return True
        return not starts_at_rest(
            self.measured,
            self.valid,
            self.noise_std,
            self.n_samples,
            self.sample_period_s,
            self.kinds,
        )

    def delayed(self, latency: Mapping[str, int]) -> Dataset:
        """The dataset with each channel named in ``latency`` advanced by its latency of d
        samples (``FitOptions.latency_samples``), its last d samples invalid; ``at_rest`` as
        the advanced channels show (``shows_rest``)."""
        if not any(latency.get(name, 0) for name in self.names):
            return self
        measured, valid = self.measured.copy(), self.valid.copy()
        for j, name in enumerate(self.names):
            lag = latency.get(name, 0)
            if lag:
                measured[:-lag, j], valid[:-lag, j] = measured[lag:, j], valid[lag:, j]
                valid[-lag:, j] = False
        moved = replace(self, measured=np.where(valid, measured, np.nan), valid=valid)
        return replace(moved, at_rest=moved.shows_rest())


def check_excitation(experiments: Sequence[Dataset]) -> tuple[str, ...]:
    """The names of the ``experiments`` that do not excite the model (``Dataset.excites``),
    which a fit together with one that does may carry; ``FitError`` naming the recordings
    and their inputs if not one excites it (a fit of them would end "converged" with no
    parameter identified)."""
    resting = tuple(e.name for e in experiments if not e.excites)
    if experiments and len(resting) == len(experiments):
        raise FitError(
            f"{', '.join(resting)}: nothing excites the model: inputs "
            f"{', '.join(experiments[0].input_names)} constant and the plant at rest "
            f"throughout {'the recording' if len(resting) == 1 else 'every recording'}"
        )
    return resting


def state_outputs(model: Model) -> np.ndarray:
    """(n_y,) the index of the state each output is (y_j = x_i: a coordinate, or a rate a
    tachometer measures), -1 for an output that is any other function of (x, u, p)."""
    x = ca.SX.sym("x", model.n_states)
    u = ca.SX.sym("u", model.n_inputs)
    p = ca.SX.sym("p", len(model.parameters))
    y = model.output_map(x, u, p)
    index = np.full(y.numel(), -1)
    for j in range(y.numel()):
        slope = ca.jacobian(y[j], ca.vertcat(x, u, p))
        offset = ca.substitute(y[j], x, ca.SX.zeros(model.n_states))
        if ca.depends_on(slope, ca.vertcat(x, u, p)) or not offset.is_zero():
            continue
        row = np.array(ca.evalf(slope)).ravel()
        if np.count_nonzero(row) == 1 and row[: model.n_states].max() == 1.0:
            index[j] = int(np.argmax(row))
    return index


def output_kinds(model: Model) -> tuple[str, ...]:
    """Per output: ``"position"`` (a coordinate), ``"rate"`` (a coordinate's rate) or
    ``"other"`` (any other function of the state, inputs and parameters)."""
    nq = model.n_states // 2
    return tuple(
        "other" if i < 0 else "position" if i < nq else "rate" for i in state_outputs(model)
    )


def starts_at_rest(
    outputs: np.ndarray,
    valid: np.ndarray,
    channel_std: np.ndarray,
    samples: int,
    dt: float,
    kinds: Sequence[str] | None = None,
) -> bool:
    """Whether a record shows rest at its start: per channel of ``outputs`` (N, n_y), y = a +
    b t + c t^2 fitted to its ``valid`` samples among the first ``samples``, and no |b| above
    ``REST_Z`` of its standard error (white noise of ``channel_std`` [SI]). A record cut in
    motion starts with a velocity (b); one at rest, or accelerating slowly from it, does
    not. ``kinds`` (``output_kinds``, default all positions): a channel measuring a rate
    shows rest by its value (|a| within ``REST_Z`` standard errors of 0); another function
    of the state (a motor current) tells nothing and is not tested. Too few samples, or no
    channel to tell: at rest is not assumed."""
    kinds = kinds or ("position",) * outputs.shape[1]
    t = np.arange(min(samples, outputs.shape[0])) * dt
    design = np.stack([np.ones_like(t), t, t**2], axis=1)
    tested = [j for j in range(outputs.shape[1]) if kinds[j] != "other"]
    if not tested:
        return False
    for j in tested:
        used = valid[: t.size, j]
        if np.count_nonzero(used) <= design.shape[1]:
            return False
        a = design[used]
        coef, *_ = np.linalg.lstsq(a, outputs[: t.size, j][used], rcond=None)
        term = 0 if kinds[j] == "rate" else 1
        std = channel_std[j] * math.sqrt(np.linalg.inv(a.T @ a)[term, term])
        if abs(coef[term]) > REST_Z * std:
            return False
    return True
