"""Predicted information of experiments: what a fit of their recordings would know.

Each input table is simulated at given parameters from rest (noise-free, through the rig's
DAC, by the transcription's own integrator: ``simulate_experiments``),
measured as the rig measures it (a laser sample outside the laser's range, +/-5 cm on the
thesis's rig, is invalid), and transcribed as ``hframe-id fit`` transcribes recordings
(``build_problem`` with the fit's options, ``MultipleShooting``). At the simulated solution
the continuity holds, and ``GaussNewton.condensed_jacobian`` gives the single-shooting
Jacobian J of the weighted residuals (units of each channel's noise std) with respect to
each record's estimated initial state and the free parameters theta (relative changes,
``FitProblem.parameters``). The Fisher information about theta is

    F = J_t^T J_t - J_t^T J_0 (J_0^T J_0)^-1 J_0^T J_t      (initial states eliminated)

(docs/fitting.md, "Identifiability"), the same matrix the fitter's ``"gauss-newton"``
covariance s^2 F^-1 inverts; the ``"noise-model"`` standard errors (encoder quantization
along the predicted motion, ``hframe_id.fitting.statistics``) come from the same J.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from hframe_id.errors import FitError
from hframe_id.fitting.link_options import TranscriptionOptions
from hframe_id.fitting.options import FitOptions
from hframe_id.fitting.problem import FitProblem, build_problem
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.fitting.solver import GaussNewton
from hframe_id.fitting.statistics import Block, compute_statistics
from hframe_id.models import Model
from hframe_id.parameters import ParameterSet
from hframe_id.recordings.log_format import NOISE_STD_PREFIX
from hframe_id.recordings.recording import Recording
from hframe_id.recordings.sensors import LASER_OUTPUTS, SensorModel


def reduced_information(jac: np.ndarray, n_nuisance: int) -> np.ndarray:
    """Information J^T J about the parameters (the last columns of ``jac``) with the first
    ``n_nuisance`` columns (initial states) eliminated: the Schur complement."""
    info = jac.T @ jac
    if not n_nuisance:
        return info
    a = info[:n_nuisance, :n_nuisance]
    b = info[:n_nuisance, n_nuisance:]
    return info[n_nuisance:, n_nuisance:] - b.T @ np.linalg.lstsq(a, b, rcond=None)[0]


def rig_metadata(sensors: SensorModel) -> dict:
    """The rig metadata of a predicted recording: the sensors' and the DAC's specification
    (what ``build_problem`` reads for the noise levels and the DAC)."""
    return {"backend": "design", **sensors.as_metadata()}


def predicted_recording(
    model: Model,
    commanded: np.ndarray,
    states: np.ndarray | None,
    rig: dict,
    sample_period_s: float,
    name: str,
    variant: str,
) -> Recording:
    """A noise-free recording of ``commanded`` (N, n_u) [V] whose plant went through
    ``states`` (N + 1, n_x), each laser sample outside the rig's laser range
    (``laser_min_m``/``laser_max_m`` [m]) invalid; ``states`` None: a placeholder at rest,
    every sample valid (to set up the transcription that simulates it)."""
    commanded = np.atleast_2d(np.asarray(commanded, dtype=float))
    n = commanded.shape[0]
    outputs = np.zeros((n, len(model.outputs)))
    if states is not None:
        outputs = np.array(model.output.map(n)(states[:-1].T)).T
    valid = np.ones_like(outputs, dtype=bool)
    low = float(rig.get("laser_min_m", -math.inf))
    high = float(rig.get("laser_max_m", math.inf))
    for j, s in enumerate(model.outputs):
        if s.name in LASER_OUTPUTS:
            valid[:, j] = (outputs[:, j] >= low) & (outputs[:, j] <= high)
    return Recording(
        variant=variant,
        sample_period_s=sample_period_s,
        time_s=np.arange(n) * sample_period_s,
        inputs=commanded,
        input_names=tuple(s.name for s in model.inputs),
        outputs=np.where(valid, outputs, np.nan),
        output_names=tuple(s.name for s in model.outputs),
        valid=valid,
        rig=dict(rig),
        experiment={"design": name},
    )


def simulate_experiments(
    problem: FitProblem, transcription: TranscriptionOptions | None = None
) -> list[np.ndarray]:
    """Per experiment of ``problem``, the (N + 1, n_x) states from rest at the origin at its
    initial parameters, through the rig's DAC (the problem's inputs): the transcription's own
    compiled integrator (``MultipleShooting.fill_nodes`` chains the nodes, ``evaluate`` the
    samples between them), ``transcription`` (default: the model's)."""
    ms = MultipleShooting(problem, transcription=transcription)
    theta = np.zeros(len(problem.free))
    known = np.zeros(ms.n_windows, dtype=bool)
    nodes = ms.fill_nodes(np.zeros((ms.n_windows, ms.nx)), known, theta, problem.smoothing)
    ev = ms.evaluate(nodes, theta, problem.smoothing, derivatives=False)
    all_states = []
    for e in range(len(problem.experiments)):
        windows = np.flatnonzero(ms.window_experiment == e)
        parts = [ev.states[w, : ms.window_length[w]] for w in windows]
        last = windows[-1]
        parts.append(ev.states[last, ms.window_length[last]][None, :])
        all_states.append(np.concatenate(parts))
    return all_states


@dataclass(frozen=True)
class Information:
    """What a joint fit of some experiments would know about the free parameters.

    Attributes
    ----------
    names : the free parameters, in the order of theta.
    matrix : (n_f, n_f) Fisher information about theta (relative changes), initial states
        eliminated, residuals in units of each channel's noise std.
    slopes : (n_f,) d p / d theta at the parameters [SI] (p for log-scale parameters).
    values : (n_f,) the free parameters' values [SI].
    jacobian : condensed Jacobian (rows: valid weighted residuals; nuisance columns first).
    blocks : its rows per experiment and channel, with their noise model.
    n_nuisance : its initial-state columns.
    experiment_rows : per experiment, (its rows of ``jacobian``, its nuisance columns).
    states : per experiment, the (N + 1, n_x) simulated states.
    outputs : per experiment, the (N, n_y) noise-free outputs [SI], also where a sensor
        is out of range.
    valid : per experiment, the (N, n_y) samples a fit would use.
    output_names : the model's outputs.
    """

    names: tuple[str, ...]
    matrix: np.ndarray
    slopes: np.ndarray
    values: np.ndarray
    jacobian: np.ndarray
    blocks: tuple[Block, ...]
    n_nuisance: int
    experiment_rows: tuple[tuple[np.ndarray, np.ndarray], ...]
    states: tuple[np.ndarray, ...]
    outputs: tuple[np.ndarray, ...]
    valid: tuple[np.ndarray, ...]
    output_names: tuple[str, ...]

    def relative_std(self, prior: np.ndarray | None = None) -> np.ndarray:
        """(n_f,) predicted standard errors of theta (relative for log-scale parameters)
        with white noise of the channels' std: sqrt(diag((F + prior)^-1)); inf for a
        parameter the experiments carry no information about."""
        return standard_errors(self.matrix if prior is None else self.matrix + prior)

    def predicted_relative_std(self) -> np.ndarray:
        """(n_f,) the standard errors of theta a fit would report: per parameter the larger of
        the white-noise (``relative_std``) and the ``noise-model`` errors, as the fit's
        ``"robust"`` errors take the larger of its HAC (white residuals: the textbook ones)
        and noise-model errors."""
        return np.maximum(self.relative_std(), self.noise_model_relative_std())

    def noise_model_relative_std(self) -> np.ndarray:
        """(n_f,) predicted ``noise-model`` standard errors of theta: the fitter's bootstrap
        of encoder quantization and laser noise along the predicted motion
        (``compute_statistics``), seeded as there."""
        residual = np.zeros(self.jacobian.shape[0])
        stats = compute_statistics(
            self.jacobian, residual, list(self.blocks), self.n_nuisance, self.names, "noise-model"
        )
        return stats.relative_std_noise

    def per_experiment(self) -> list[np.ndarray]:
        """Each experiment's own information (n_f, n_f), its initial state eliminated."""
        theta = np.arange(self.n_nuisance, self.jacobian.shape[1])
        return [
            reduced_information(self.jacobian[np.ix_(rows, np.r_[columns, theta])], columns.size)
            for rows, columns in self.experiment_rows
        ]


def standard_errors(info: np.ndarray) -> np.ndarray:
    """sqrt(diag(info^-1)) by a pseudo-inverse scaled to unit diagonal; inf where the
    diagonal is 0 (no information)."""
    d = np.sqrt(np.maximum(np.diag(info), 0.0))
    blind = d <= 0
    d = np.where(blind, 1.0, d)
    cov = np.linalg.pinv(info / np.outer(d, d), rcond=1e-13, hermitian=True) / np.outer(d, d)
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    std[blind] = math.inf
    return std


def design_options(free: Sequence[str], channel_std: Mapping[str, float] | None = None):
    """The fit's options for predicting a design: ``hframe-id fit``'s defaults
    (``FitOptions()``) with the free parameters ``free`` and, if given, the channels' noise
    std ``channel_std`` (output name -> SI) instead of the sensors', on the transcription of
    the fit's last solve (``rest_start`` "replay": a record at rest from the replay's rest
    state, ``fitting.replayed_rest``), where its statistics are computed."""
    return FitOptions(free=tuple(free), channel_std=dict(channel_std or {}), rest_start="replay")


def fitted_channel_std(params: ParameterSet) -> dict[str, float]:
    """The noise levels a fit that made ``params`` weighted its channels with, when it
    estimated them from its residuals (``provenance.noise``: the model did not follow the
    data at the sensors' noise level): output name -> std [SI]; else none (the sensors').

    A fit of a new recording of the same rig will meet the same misfit and weigh by it; a
    prediction with the sensors' noise would promise it errors 50-3000 x too small (measured
    on a realistic plant's six steps, docs/studies/2026-11-26-design.md)."""
    noise = params.provenance.get("noise")
    if not isinstance(noise, Mapping) or noise.get("weights") != "estimated from the residuals":
        return {}
    levels = {}
    for output, entry in (noise.get("channels") or {}).items():
        if not isinstance(entry, Mapping):
            continue
        for key, value in entry.items():
            if str(key).startswith("weight_std") and isinstance(value, int | float) and value > 0:
                levels[str(output)] = float(value)
    return levels


def experiment_information(
    params: ParameterSet,
    tables: Sequence[np.ndarray],
    options: FitOptions,
    sensors: SensorModel | None = None,
    sample_period_s: float = 1e-3,
    rig: dict | None = None,
    names: Sequence[str] | None = None,
) -> Information:
    """The information of a joint fit of the experiments ``tables`` (each (N, n_u) commanded
    voltages [V]) at ``params``, with the fit's ``options`` (free parameters, weights,
    transcription).

    The rig is ``rig`` (metadata as a recording carries them) or else the ``sensors``
    (default: the thesis's rig, ``SensorModel()``). Raises ``FitError`` when the fit could
    not be set up (``build_problem``: too few valid samples, unknown free parameters).
    """
    from hframe_id.models import build_model

    model = build_model(params.variant)
    rig = dict(rig) if rig is not None else rig_metadata(sensors or SensorModel())
    names = list(names) if names is not None else [f"design-{i}" for i in range(len(tables))]
    if len(names) != len(tables):
        raise FitError(f"{len(names)} names for {len(tables)} experiments")

    def recordings(all_states, metadata):
        return [
            predicted_recording(
                model, table, states, metadata, sample_period_s, name, params.variant
            )
            for name, table, states in zip(names, tables, all_states, strict=True)
        ]

    # The placeholder only simulates: its noise levels are declared (1 SI), so that a rig
    # whose levels are estimated from the data does not estimate them from its zeros.
    declared = {**rig, **{NOISE_STD_PREFIX + s.name: 1.0 for s in model.outputs}}
    placeholder = build_problem(recordings([None] * len(tables), declared), params, options)
    transcription = options.for_model(params.variant).transcription_options
    all_states = simulate_experiments(placeholder, transcription)
    problem = build_problem(recordings(all_states, rig), params, options)
    return _information(problem, all_states, transcription)


def _information(
    problem: FitProblem, all_states: list[np.ndarray], transcription: TranscriptionOptions
) -> Information:
    """``Information`` of ``problem`` (at its initial parameters, theta = 0) from the
    simulated states of its experiments, transcribed by ``transcription``."""
    ms = MultipleShooting(problem, transcription=transcription)
    nodes = np.array(
        [all_states[e][k] for e, k in zip(ms.window_experiment, ms.window_start, strict=True)]
    )
    theta = np.zeros(len(problem.free))
    ev = ms.evaluate(nodes, theta, problem.smoothing)
    jac, _, blocks = GaussNewton(ms).condensed_jacobian(
        ev, nodes, np.ones(len(problem.free), dtype=bool)
    )
    if not np.all(np.isfinite(jac)):
        raise FitError("the predicted sensitivities are not finite at these parameters")
    experiment_rows = []
    column = 0
    ny = len(problem.output_names)
    for e, basis in enumerate(ms.initial_state_bases):
        # ``condensed_jacobian`` lists the blocks experiment by experiment, channel by channel.
        rows = np.concatenate([b.rows for b in blocks[e * ny : (e + 1) * ny]])
        n = basis.shape[1]
        experiment_rows.append((np.sort(rows), np.arange(column, column + n)))
        column += n
    p = problem.parameters(theta)
    prior = problem.prior_weight
    info = Information(
        names=problem.free_names,
        matrix=np.diag(prior**2),
        slopes=problem.parameter_slopes(p),
        values=p[list(problem.free)],
        jacobian=jac,
        blocks=tuple(blocks),
        n_nuisance=ms.n_nuisance,
        experiment_rows=tuple(experiment_rows),
        states=tuple(all_states),
        outputs=tuple(states[:-1] @ ms.c.T for states in all_states),
        valid=tuple(e.valid for e in problem.experiments),
        output_names=problem.output_names,
    )
    # The experiments' initial states are separate unknowns: the Schur complement of the
    # joint information is the sum of the experiments' own ones.
    return replace(info, matrix=info.matrix + sum(info.per_experiment()))
