"""Choose the blocks of a design: the best criterion over a few parameter sets, travel kept.

The design problem, made small: a design of ``Layout.n_blocks`` blocks picks each one from
the candidate blocks (``excitation.candidate_blocks``: 64 doublets). Each candidate is
simulated once per parameter set from rest (``information.experiment_information``, all
candidates as the experiments of one fit) for

- its information F_kc (parameter set k, candidate c), and
- its travel: the extremes of x and y [m] on the model.

A candidate whose travel from rest leaves the limits less the margin in any parameter set
is not used. Doublets come back to where they started (``excitation``), so the information
of a sequence of blocks is close to the sum of theirs, and the choice maximises

    mean_k criterion(P_k + sum_{b in design} F_kb)

(``criteria.Criterion``; P_k the prior information: ``RIDGE`` I, plus what recordings
already made carry) by a greedy fill and exchange passes (Fedorov's exchange on a finite
candidate set; deterministic). The chosen sequence is then simulated whole at every
parameter set: its exact information is what the report predicts, and if its travel breaks
the limits less the margin anywhere (a slow drift of the chained blocks), the block that
travels farthest is dropped from the candidates and the choice made again.

Robustness to the parameters: the parameter sets are the file's values and ``draws`` sets
drawn (``numpy.random.default_rng(seed)``) log-normally around them with each free
parameter's relative standard error from the file's ``uncertainty`` (a fit's), at least
``MIN_RELATIVE_SPREAD``: a fit's standard errors understate its real errors on a plant the
model does not match (2-33 x, docs/fitting.md), and a table has none.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from hframe_id.design.criteria import Criterion
from hframe_id.design.excitation import Block, Layout, candidate_blocks
from hframe_id.design.information import (
    Information,
    design_options,
    experiment_information,
    fitted_channel_std,
)
from hframe_id.errors import FitError, OptionError
from hframe_id.fitting.options import FitOptions
from hframe_id.parameters import ParameterSet
from hframe_id.recordings.sensors import SensorModel

#: Prior information about each theta: a relative std of 10 (e^10 in log scale), nothing
#: known; it makes the criteria finite before every parameter has information.
RIDGE = 1e-2
#: Smallest relative spread [-] of the parameter draws (see the module docstring).
MIN_RELATIVE_SPREAD = 0.1
#: Largest relative spread [-] (std of the log) of the draws: a parameter the file's fit
#: hardly determined (measured: relative standard errors up to 1e3 on a six-step fit of a
#: realistic plant) is drawn within about x/÷2.7 at two sigma, not over decades, which
#: would design for plants that do not exist.
MAX_RELATIVE_SPREAD = 0.5
#: Distance [m] kept from each travel limit on the model by default: a quarter of the
#: thesis's +/-0.2 m, for a plant that moves farther than its parameters say.
TRAVEL_MARGIN_M = 0.05
#: Exchange passes over the blocks after the greedy fill (each stops early without gain).
EXCHANGE_PASSES = 3
#: Candidates simulated as the experiments of one fit problem: the condensed Jacobian's
#: size grows with the square of the experiments (each brings its initial-state columns).
CHUNK = 8
#: Choices made again after a whole sequence broke the travel limits.
TRAVEL_RETRIES = 6


@dataclass(frozen=True)
class Limits:
    """What the rig allows: ``max_voltage_v`` [V] on each motor, and per axis (``x``, ``y``)
    the travel (low, high) [m] from where the record starts, kept ``margin_m`` [m] away
    from on the model."""

    max_voltage_v: float
    travel_m: Mapping[str, tuple[float, float]]
    margin_m: float = TRAVEL_MARGIN_M

    def check(self, sensors: SensorModel) -> None:
        """``OptionError`` (naming the option and value) for a voltage the DAC cannot give,
        or a travel that does not hold the start position (0 m) with the margin."""
        if not (math.isfinite(self.max_voltage_v) and self.max_voltage_v > 0):
            raise OptionError(f"--max-voltage must be > 0 V, got {self.max_voltage_v!r}")
        top = min(sensors.dac_max_v, -sensors.dac_min_v)
        if self.max_voltage_v > top:
            raise OptionError(
                f"--max-voltage {self.max_voltage_v:g} V is above the DAC range "
                f"[{sensors.dac_min_v:g}, {sensors.dac_max_v:g}] V"
            )
        if not (math.isfinite(self.margin_m) and self.margin_m >= 0):
            raise OptionError(f"--margin must be >= 0 m, got {self.margin_m!r}")
        for axis in ("x", "y"):
            if axis not in self.travel_m:
                raise OptionError(f"--travel {axis}=LOW:HIGH is missing")
        for axis, (low, high) in self.travel_m.items():
            if not (low + self.margin_m < 0 < high - self.margin_m):
                raise OptionError(
                    f"--travel {axis}={low:g}:{high:g}: the record starts at 0 m, which must "
                    f"lie inside the travel with the {self.margin_m:g} m margin on each side"
                )

    def overshoot(self, reach: Mapping[str, tuple[float, float]]) -> float:
        """How far [m] ``reach`` goes past the limits less the margin (<= 0: inside)."""
        return max(
            max(low + self.margin_m - reach[a][0], reach[a][1] - (high - self.margin_m))
            for a, (low, high) in self.travel_m.items()
        )


@dataclass(frozen=True)
class DesignOptions:
    """How to design: the criterion, the robustness draws and the fit's settings.

    Attributes
    ----------
    criterion : what to optimise (D-optimal by default).
    free : the free parameters (default: the file's fit's, else the model's default set).
    draws : parameter sets drawn around the file's values besides them.
    seed : seeds the draws.
    sample_period_s : the rig's sample period [s].
    sensors : the rig's sensors and DAC (default: the thesis's rig).
    prior_tables : input tables (N, 2) [V] of recordings already made: their information
        at each parameter set is added to the design's (a sequential design).
    """

    criterion: Criterion = field(default_factory=Criterion)
    free: tuple[str, ...] | None = None
    draws: int = 2
    seed: int = 0
    sample_period_s: float = 1e-3
    sensors: SensorModel = field(default_factory=SensorModel)
    prior_tables: tuple[np.ndarray, ...] = ()

    def __post_init__(self) -> None:
        if self.draws < 0:
            raise OptionError(f"--draws must be >= 0, got {self.draws}")


@dataclass(frozen=True)
class Design:
    """A designed excitation and what it is predicted to give.

    Attributes
    ----------
    blocks : the chosen blocks, in order.
    table : (N, 2) voltages [V], one row per sample.
    information : the whole design's information at the file's parameters.
    criterion : the criterion optimised.
    value : its value averaged over the parameter sets (smaller is better).
    reach : per parameter set, per axis, (min, max) [m] of the predicted motion.
    motion : per parameter set, the (N, axes) predicted positions [m] of the travel's axes.
    parameter_sets : the file's values and the draws.
    prior : per parameter set, the prior information (ridge and recordings already made).
    fit_options : the fit's options the predictions were made with (free parameters, and
        the channels' noise: ``fitted_channel_std``).
    wall_time_s : how long the design took [s].
    """

    blocks: tuple[Block, ...]
    table: np.ndarray
    information: Information
    criterion: Criterion
    value: float
    reach: tuple[dict[str, tuple[float, float]], ...]
    motion: tuple[np.ndarray, ...]
    parameter_sets: tuple[ParameterSet, ...]
    prior: tuple[np.ndarray, ...]
    fit_options: FitOptions
    wall_time_s: float


def free_parameters(params: ParameterSet, free: Sequence[str] | None) -> tuple[str, ...]:
    """The free parameters: ``free`` (names or patterns, as ``hframe-id fit --free``), else
    the fit's that made the file (``provenance.free_parameters``), else the model's default
    free set."""
    from hframe_id.fitting.problem import default_free, resolve_free
    from hframe_id.models import build_model

    model = build_model(params.variant)
    if free:
        wanted = FitOptions(free=tuple(free)).for_model(params.variant).problem_options
        try:
            return tuple(resolve_free(model, wanted))
        except FitError as err:
            raise OptionError(f"--free {','.join(free)}: {err}") from None
    fitted = params.provenance.get("free_parameters")
    if isinstance(fitted, list) and fitted:
        return tuple(str(n) for n in fitted)
    return tuple(default_free(model))


def relative_spread(params: ParameterSet, names: Sequence[str]) -> dict[str, float]:
    """Per free parameter, the relative std [-] of the draws: the file's standard error over
    its estimate (``uncertainty.parameters``), within [``MIN_RELATIVE_SPREAD``,
    ``MAX_RELATIVE_SPREAD``]."""
    listed = params.uncertainty.get("parameters", {})
    by_name = {str(key).split(" [")[0]: entry for key, entry in listed.items()}
    spread = {}
    for name in names:
        entry = by_name.get(name) or {}
        std, estimate = entry.get("std_error"), entry.get("estimate")
        relative = 0.0
        if isinstance(std, int | float) and isinstance(estimate, int | float) and estimate:
            relative = abs(float(std) / float(estimate))
        relative = relative if math.isfinite(relative) else MAX_RELATIVE_SPREAD
        spread[name] = min(max(relative, MIN_RELATIVE_SPREAD), MAX_RELATIVE_SPREAD)
    return spread


def parameter_draws(
    params: ParameterSet, names: Sequence[str], draws: int, seed: int
) -> list[ParameterSet]:
    """``params`` and ``draws`` sets with each of ``names`` multiplied by exp(s z), z standard
    normal from ``default_rng(seed)``, s its ``relative_spread``."""
    rng = np.random.default_rng(seed)
    spread = relative_spread(params, names)
    sets = [params]
    for _ in range(draws):
        z = rng.standard_normal(len(names))
        changes = {
            n: params.values[n] * math.exp(spread[n] * float(zi))
            for n, zi in zip(names, z, strict=True)
        }
        sets.append(params.replace_values(**changes))
    return sets


def _reach(info: Information, experiment: int, axes: Sequence[str]) -> dict:
    """Per axis, (min, max) [m] of experiment ``experiment``'s predicted motion."""
    outputs = info.outputs[experiment]
    return {
        a: (
            float(np.min(outputs[:, info.output_names.index(a)])),
            float(np.max(outputs[:, info.output_names.index(a)])),
        )
        for a in axes
    }


def choose(
    candidates: Sequence[Sequence[np.ndarray]],
    prior: Sequence[np.ndarray],
    allowed: np.ndarray,
    n_blocks: int,
    criterion: Criterion,
    focus_index: np.ndarray | None = None,
) -> list[int]:
    """The candidates (indices, with repetition) of a design of ``n_blocks`` blocks: greedy,
    then exchange passes, minimising mean_k criterion(prior_k + sum F_kb) over the parameter
    sets k; ``candidates[k][c]`` is F_kc, ``allowed`` (C,) the candidates that may be used."""
    usable = np.flatnonzero(allowed)
    if not usable.size:
        return []

    def score(chosen: Sequence[int]) -> float:
        total = 0.0
        for k, infos in enumerate(candidates):
            info = prior[k] + sum((infos[c] for c in chosen), np.zeros_like(prior[k]))
            total += criterion.value(info, focus_index)
        return total / len(candidates)

    chosen: list[int] = []
    for _ in range(n_blocks):
        chosen.append(min(usable, key=lambda c: score([*chosen, c])))
    best = score(chosen)
    for _ in range(EXCHANGE_PASSES):
        improved = False
        for slot in range(n_blocks):
            for c in usable:
                trial = [*chosen[:slot], c, *chosen[slot + 1 :]]
                value = score(trial)
                if value < best - 1e-12:
                    chosen, best, improved = trial, value, True
        if not improved:
            break
    return [int(c) for c in chosen]


def design_experiment(
    params: ParameterSet,
    duration_s: float,
    limits: Limits,
    options: DesignOptions | None = None,
) -> Design:
    """Design an excitation of ``duration_s`` [s] for the model and parameters of ``params``
    within ``limits`` (``OptionError`` for limits the rig cannot meet or a design that
    cannot identify any free parameter)."""
    start = time.perf_counter()
    options = options or DesignOptions()
    limits.check(options.sensors)
    layout = Layout(duration_s, options.sample_period_s)
    names = free_parameters(params, options.free)
    fit_options = design_options(names, fitted_channel_std(params))
    focus_index = options.criterion.indices(names) if options.criterion.focus else None
    sets = parameter_draws(params, names, options.draws, options.seed)
    library = candidate_blocks(limits.max_voltage_v)
    tables = [layout.block_table(b) for b in library]
    axes = tuple(limits.travel_m)
    candidates, priors = [], []
    # (sets, candidates) how far past the limits less the margin each candidate goes.
    overshoot = np.zeros((len(sets), len(library)))
    for k, theta_set in enumerate(sets):
        candidates.append([])
        for first in range(0, len(library), CHUNK):
            info = _information(theta_set, tables[first : first + CHUNK], fit_options, options)
            candidates[k] += info.per_experiment()
            overshoot[k, first : first + CHUNK] = [
                limits.overshoot(_reach(info, c, axes)) for c in range(len(info.states))
            ]
        prior = RIDGE * np.eye(len(names))
        if options.prior_tables:
            prior = (
                prior
                + _information(theta_set, list(options.prior_tables), fit_options, options).matrix
            )
        priors.append(prior)
    reach_ok = np.all(overshoot <= 0, axis=0)
    travel = ", ".join(f"{a}={lo:g}:{hi:g} m" for a, (lo, hi) in limits.travel_m.items())
    if not np.any(reach_ok):
        raise OptionError(
            f"--travel {travel}: every candidate block of up to {limits.max_voltage_v:g} V "
            f"moves the model of {params.where()} past the travel less the "
            f"{limits.margin_m:g} m margin; lower --max-voltage or widen --travel"
        )
    nominal_total = sum(candidates[0][c] for c in np.flatnonzero(reach_ok))
    if not np.any(np.diag(nominal_total) > 0):
        raise OptionError(
            f"no free parameter with information: no block of up to {limits.max_voltage_v:g} V "
            f"moves the model of {params.where()} within the travel ({travel}, margin "
            f"{limits.margin_m:g} m)"
        )
    if focus_index is not None:
        blind = [names[i] for i in focus_index if not nominal_total[i, i] > 0]
        if blind:
            raise OptionError(f"--focus {', '.join(blind)}: no design here carries information")
    for _ in range(TRAVEL_RETRIES + 1):
        chosen = choose(
            candidates, priors, reach_ok, layout.n_blocks, options.criterion, focus_index
        )
        blocks = tuple(library[c] for c in chosen)
        table = layout.table(blocks)
        infos = [_information(s, [table], fit_options, options) for s in sets]
        reach = tuple(_reach(info, 0, axes) for info in infos)
        worst = max(range(len(sets)), key=lambda k: limits.overshoot(reach[k]))
        if limits.overshoot(reach[worst]) <= 0:
            break
        # Drop the chosen block that, from rest, comes nearest the limits in the worst set.
        far = max(set(chosen), key=lambda c: overshoot[worst, c])
        reach_ok[far] = False
    else:
        raise OptionError(
            f"no design of {duration_s:g} s found that keeps the travel limits with the "
            f"{limits.margin_m:g} m margin; lower --max-voltage or widen --travel"
        )
    values = [
        options.criterion.value(info.matrix + prior, focus_index)
        for info, prior in zip(infos, priors, strict=True)
    ]
    return Design(
        blocks=blocks,
        table=table,
        information=infos[0],
        criterion=options.criterion,
        value=float(np.mean(values)),
        reach=reach,
        motion=tuple(
            info.outputs[0][:, [info.output_names.index(a) for a in axes]] for info in infos
        ),
        parameter_sets=tuple(sets),
        prior=tuple(priors),
        fit_options=fit_options,
        wall_time_s=time.perf_counter() - start,
    )


def _information(
    params: ParameterSet, tables: Sequence[np.ndarray], fit_options: FitOptions, options
) -> Information:
    """``experiment_information`` with the design's rig."""
    return experiment_information(
        params, tables, fit_options, options.sensors, options.sample_period_s
    )
