"""Never worse than a point the fit knows: the final criterion at other parameter sets.

A local optimizer can stop in a poorer optimum than a point it has seen or could have seen.
Here the criterion that judges the written parameter file is evaluated at the fit and at
the points it knows (issue 25, "never worse than a point it knows"):

- the start (``FitResult.initial``),
- the equation-error estimate (``equation_error.equation_error_start``),
- the model's reference files (the declaration's reference file and every other parameter
  file of the same model beside it, e.g. Tables 4.1 and 4.2 for hframe-8),
- the sets the user names (``FitOptions.known_points``).

The criterion is a free-run simulation of each training recording
(``validation.replay.simulate_channels``) from the fit's estimated initial state (a record
at rest: velocities zero, belts unstretched, the belt-free position estimated:
``MultipleShooting.node_projector``; within a third of an encoder step of the replay's rest
state on matched data, where it is worth 8 chi^2/2 units on 4V_xmotion.mcap); for a fit
that failed, from the better of that and the replay's rest state (what ``validate`` starts a
record at rest from: a failed fit's estimated positions can be far off, from where every
other point looks worse) (``judged_starts``). The written file's criterion as ``validate``
replays it (``replayed_starts``) is measured too (``KnownPointsReport.replayed``): a success
must beat by it the model with its inputs held (``unforced``) and each channel held at its
mean (``fit._explaining_the_data``). Residuals are weighted by
the sensors' noise std per channel,

    C(p) = 1/2 sum_recordings sum_channels sum_valid samples ((y - y_sim(p)) / std_j)^2,

or, where the fit estimated its noise levels (model mismatch: one per recording e and
channel j, ``noise_rounds``), concentrated over them: every point gets the levels
s_ej >= sensor std_j that suit it best,

    C(p) = sum_ej N_ej / 2 ln(s_ej^2) + SSR_ej(p) / (2 s_ej^2) - N_ej / 2,
    s_ej^2 = max(SSR_ej(p) / N_ej, std_j^2),

which is sum_ej N_ej / 2 ln(SSR_ej / N_ej) while every channel is above its sensor's noise. The
floor is the noise rounds' (``noise_rounds.noise_levels``): without it a point that fits one
channel below its sensor's noise gains without bound (ln 0) whatever it does to the others.
Judged under the fit's own levels, which come from its own residuals, any other point would
be judged on the fit's terms (a seeded start of the lubricated plant failed at 3.6 rad
motor-angle rms with noise levels of 1.5-2 rad, under which Table 4.2 looked 300 x worse than
it). Judged from that failed fit's own initial states only, likewise: its estimated initial
positions made every other point look worse than its 4.6 rad free run from rest. Differences
of either are likelihood-ratio statistics (``Criterion``).

Each known point enters with the fit's fixed parameters and its own values of the free ones,
clipped into the user's bounds, not into the default box drawn around the start
(``fit._known_candidates``). A point counts as better when its criterion is lower by more
than ``open_ended.LIKELIHOOD_RATIO_95`` (1.92: significant at 95 %). A fit that failed is
continued from each point other than its start, best first, until a continuation succeeds
no worse than the failed fit's end (``fit._never_worse_than_known``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from hframe_id.errors import HframeIdError
from hframe_id.parameters import ParameterSet, load_parameter_file
from hframe_id.recordings.recording import Recording


@dataclass(frozen=True)
class KnownPoint:
    """A parameter set the fit is judged against, and its criterion."""

    label: str
    parameters: ParameterSet
    criterion: float  # C(p) (``Criterion``); inf where the simulation fails


@dataclass(frozen=True)
class KnownPointsReport:
    """A fit judged against the points it knows, by the criterion ``criterion`` names
    (``Criterion.name``); every number is that criterion, C(p) of the module docstring
    (dimensionless: chi^2 / 2 units, or the concentrated criterion's), inf where the
    simulation failed. ``fit``: the fit's own, from the initial states the points are judged
    from (``judged_starts``); ``points``: each known point's by its label, best first;
    ``continued``: by the label of the point it started from, each fit continued from a point
    (inf for one that failed), in the order they were tried; ``replayed``: the fit's
    replayed as ``validate`` replays its written file (``replayed_starts``: a record at rest
    from the replay's rest state), nan until measured."""

    criterion: str
    fit: float
    points: dict[str, float]
    continued: dict[str, float] = field(default_factory=dict)
    replayed: float = math.nan

    @property
    def compared(self) -> dict[str, float]:
        """What the fit was compared with, by label: the known points, then the fits continued
        from them (``"fit continued from <label>"``)."""
        continued = {f"fit continued from {k}": v for k, v in self.continued.items()}
        return {**self.points, **continued}

    @property
    def criteria(self) -> dict[str, float]:
        """Every number by label, the fit's as ``"fit"`` first, then ``compared`` (the
        ``known_points`` of ``hframe-id fit --json``)."""
        return {"fit": self.fit, **self.compared}


class Simulations:
    """The free runs of one fit's training recordings, each simulated once: the start
    screen, the known points and the replay of the written file judge the same parameter
    sets from the same states (``make fit``: 8 simulations of 30 ms, 4 of them repeats).
    Keyed by the parameter values and the initial states (None: from rest); for the
    recordings of one ``fit_recordings`` call."""

    def __init__(self) -> None:
        self._runs: dict[tuple, list | None] = {}

    def of(self, params: ParameterSet, recordings, initial_states) -> list | None:
        """Per recording (``Dataset``, predicted outputs (N, n_y) [SI]), or None if a
        simulation fails."""
        key = (
            params.variant,
            tuple(sorted(params.values.items())),
            tuple(None if x0 is None else np.asarray(x0).tobytes() for x0 in initial_states),
        )
        if key not in self._runs:
            self._runs[key] = _simulated(params, recordings, initial_states)
        return self._runs[key]


def _simulated(params: ParameterSet, recordings, initial_states) -> list | None:
    """Per recording (``Dataset``, predicted outputs), or None if a simulation fails."""
    from hframe_id.validation.replay import simulate_channels

    predictions = []
    for recording, x0 in zip(recordings, initial_states, strict=True):
        try:
            predictions.append(simulate_channels(params, recording, x0))
        except (HframeIdError, ArithmeticError, RuntimeError):
            return None
    return predictions


def simulation_criterion(
    params: ParameterSet,
    recordings: Sequence[Recording],
    channel_std: Mapping[str, float] | Sequence[Mapping[str, float]],
    latency_samples: dict[str, int] | None = None,
    initial_states: Sequence[np.ndarray | None] | None = None,
    concentrated: bool = False,
    simulations: Simulations | None = None,
) -> float:
    """C(p) of ``params`` on ``recordings`` (module docstring); ``channel_std`` [SI] per
    output (or one such mapping per recording); a channel lagging by ``latency_samples`` d
    is compared at sample k + d with the model at k; ``initial_states`` per recording (None:
    at rest). With ``concentrated`` the noise levels are not given but estimated at
    ``params`` itself, floored at ``channel_std`` (the sensors' std): the concentrated
    criterion, about sum_ej N_ej / 2 ln(SSR_ej / N_ej) over recordings e and channels j
    (N_ej valid samples, SSR_ej their sum of squared residuals), which is what a fit that
    estimates its noise levels minimises, and whose differences are likelihood-ratio
    statistics as chi^2 / 2 differences are. inf if the simulation fails or leaves the
    finite numbers. ``simulations``: the fit's free runs (``Simulations``), reused where the
    same set was simulated from the same states."""
    starts = [None] * len(recordings) if initial_states is None else initial_states
    if simulations is None:
        predictions = _simulated(params, recordings, starts)
    else:
        predictions = simulations.of(params, recordings, starts)
    if predictions is None:
        return math.inf
    return _criterion(predictions, channel_std, latency_samples, concentrated)


def held_criterion(
    recordings: Sequence[Recording],
    channel_std: Mapping[str, float] | Sequence[Mapping[str, float]],
    latency_samples: dict[str, int] | None,
    concentrated: bool,
    variant: str,
) -> float:
    """C of the model-free prediction that nothing moves: each channel of each recording
    held at the mean of its valid samples (``variant``'s channels; the reference of a 0 %
    simulation fit), under the same noise levels (per channel, or per recording and channel)
    and latencies as ``simulation_criterion``. A fit no better than this explains none of the
    data."""
    from hframe_id.models import build_model
    from hframe_id.validation.replay import channels

    model = build_model(variant)
    predictions = []
    for recording in recordings:
        data = channels(model, recording)
        held = np.zeros_like(data.measured)
        for j in range(data.measured.shape[1]):
            valid = data.measured[data.valid[:, j], j]
            held[:, j] = valid.mean() if valid.size else 0.0
        predictions.append((data, held))
    return _criterion(predictions, channel_std, latency_samples, concentrated)


def unforced(recordings: Sequence[Recording]) -> list[Recording]:
    """Each recording with every input held at its first sample's value for the whole record
    (the pre-roll's: a record that starts at rest stays at rest under it)."""
    return [
        replace(r, inputs=np.broadcast_to(r.inputs[:1], r.inputs.shape).copy()) for r in recordings
    ]


def _criterion(predictions, channel_std, latency_samples, concentrated: bool) -> float:
    """C of (``Dataset``, predicted outputs (N, n_y) [SI]) per recording (module docstring):
    a channel lagging by d samples is compared at sample k + d with the prediction at k.
    ``channel_std``: output name -> std [SI], or one such mapping per recording."""
    latency = latency_samples or {}
    total = 0.0
    for i, (data, predicted) in enumerate(predictions):
        std = channel_std if isinstance(channel_std, Mapping) else channel_std[i]
        for j, name in enumerate(data.names):
            d = int(latency.get(name, 0))
            n = data.measured.shape[0] - d
            valid = data.valid[d:, j]
            residual = (data.measured[d:, j] - predicted[:n, j])[valid]
            squares, count = float(residual @ residual), int(valid.sum())
            if not concentrated:
                total += 0.5 * squares / std[name] ** 2
            elif count:
                total += _concentrated_term(squares, count, std[name])
    return total if np.isfinite(total) else math.inf


def _concentrated_term(squares: float, count: int, floor_std: float) -> float:
    """One channel's term of the concentrated criterion: N / 2 ln(s^2) + SSR / (2 s^2) -
    N / 2 with s^2 = max(SSR / N, ``floor_std``^2) (``squares`` SSR [SI^2], ``count`` N)."""
    variance = squares / count
    if variance >= floor_std**2:
        return 0.5 * count * math.log(max(variance, math.ulp(0.0)))
    floor = floor_std**2
    return 0.5 * count * math.log(floor) + 0.5 * squares / floor - 0.5 * count


def judged_starts(result) -> tuple[list[np.ndarray | None], ...]:
    """The initial states the points are judged from by a ``FitResult``'s ``Criterion``, as
    per-record lists: the fit's estimates; for a fit that failed also the replay's rest state
    (None) for each record at rest, with the fit's estimate for one that starts in motion
    (module docstring); for a fit whose records at rest started at the replay's rest state,
    that state (None) only. (Both for every fit doubled the simulations: ``make fit`` took
    1.58-1.83 s against 1.47-1.54 s, paired runs; a converged fit's estimated states are its
    optimum's.)"""
    if result.options.rest_start == "replay":
        # Its records at rest started where the replay starts them (``replayed_rest``): the
        # same states, named as the replay names them (None), so the runs are shared.
        return (replayed_starts(result),)
    own = list(result.initial_states)
    if result.success:
        return (own,)
    return own, replayed_starts(result)


def replayed_starts(result) -> list[np.ndarray | None]:
    """The initial states ``hframe-id validate`` replays a ``FitResult``'s written file
    from, per record: the replay's rest state (None) for a record at rest, the fit's
    estimate for one that starts in motion."""
    return [
        None if experiment.at_rest else x0
        for experiment, x0 in zip(result.problem.experiments, result.initial_states, strict=True)
    ]


@dataclass(frozen=True)
class Criterion:
    """How a fit judges a parameter set: ``simulation_criterion`` on its training
    ``recordings``, under its noise levels ``channel_std`` [SI] and latencies, concentrated
    over the noise levels where the fit estimated them (``concentrated``: every point then
    gets its own levels, floored at ``channel_std``, then the sensors' std; judged under the
    fit's own, estimated from its residuals, any other point would be judged on the fit's
    terms)."""

    recordings: tuple[Recording, ...]
    channel_std: dict[str, float]
    latency_samples: dict[str, int]
    concentrated: bool
    simulations: Simulations | None = None
    #: per recording, each channel's noise level [SI] the fit reports (its estimated levels,
    #: or the sensors' std for each recording); empty: ``channel_std``
    fit_levels: tuple[dict[str, float], ...] = ()

    @classmethod
    def of(
        cls, result, recordings: Sequence[Recording], simulations: Simulations | None = None
    ) -> Criterion:
        """The criterion of a ``FitResult``'s written file (``simulations``: the fit's free
        runs, or None)."""
        noise = result.diagnostics.noise
        concentrated = noise is not None and noise.method == "estimated"
        std = dict(result.diagnostics.channel_std)
        levels = tuple(dict(std) for _ in recordings)
        if concentrated:
            std = {name: channel.sensor_std for name, channel in noise.channels.items()}
            levels = tuple(
                {name: channel.recording_std[e] for name, channel in noise.channels.items()}
                for e in range(len(recordings))
            )
        latency = dict(result.options.latency_samples)
        return cls(tuple(recordings), std, latency, concentrated, simulations, levels)

    def __call__(self, params: ParameterSet, starts=None) -> float:
        """C(params): the lowest over ``starts``, alternative per-recording lists of initial
        states (``judged_starts``; None: from rest only)."""
        return min(
            simulation_criterion(
                params,
                self.recordings,
                self.channel_std,
                self.latency_samples,
                initial_states,
                self.concentrated,
                self.simulations,
            )
            for initial_states in (starts or (None,))
        )

    def held(self, variant: str) -> float:
        """C of the prediction that nothing moves (``held_criterion``)."""
        return held_criterion(
            self.recordings, self.channel_std, self.latency_samples, self.concentrated, variant
        )

    def against_unforced(self, params: ParameterSet, initial_states) -> tuple[float, float, float]:
        """chi^2 / 2, under the noise levels the fit reports (``fit_levels``; the issue's
        training criterion; without them ``channel_std``), of ``params`` simulated from
        ``initial_states`` (per recording), of the same model from the same states with every
        input held at its value at the record's start (``unforced``: what the model says when
        the inputs drive nothing), and of each channel held at its mean (``held_criterion``).
        The first two are the test "do the inputs drive what the outputs show under this
        model"; the third, the reference of a 0 % simulation fit, "does the replay reproduce
        the records better than a flat line". All under the same levels: per recording and
        channel a difference is then N / 2 (v - r), v and r the two mean squares in those
        levels (r about 1 at the fit's own point), so a channel held still by static friction
        that no simulation follows to its sensor's noise counts against a model by at most
        N / 2, where with each prediction at its own levels it counted N / 2 ln(1 / v)
        without bound (dev plant 57 of issue 25). A plant held nearly still by friction (test
        plant 1314: motor angles within 0.04 rad, two records below one encoder step) is
        replayed by its fit better than unforced (12,000 against 15,739) and worse than its
        held means (3,161), as by its own reduction with its current limit (16,486)."""
        levels = self.fit_levels or self.channel_std
        latency = self.latency_samples
        model = simulation_criterion(
            params, self.recordings, levels, latency, initial_states, simulations=self.simulations
        )
        still = simulation_criterion(
            params, unforced(self.recordings), levels, latency, initial_states
        )
        held = held_criterion(self.recordings, levels, latency, False, params.variant)
        return model, still, held

    @property
    def name(self) -> str:
        """What the numbers are, for statements."""
        if self.concentrated:
            return (
                "concentrated simulation criterion (sum N_j / 2 ln(SSR_j / N_j): noise levels "
                "estimated at each point)"
            )
        return "simulation criterion (chi^2 / 2 under the fit's noise levels)"


def reference_sets(variant: str) -> list[tuple[str, ParameterSet]]:
    """The model's reference files: its declaration's reference file and every parameter file
    of the same model in that file's folder (label: the file name)."""
    from hframe_id.models import declaration

    reference = declaration(variant).reference_file
    if reference is None:
        return []
    sets = []
    for path in sorted({reference, *Path(reference).parent.glob("*.yaml")}):
        try:
            params = load_parameter_file(path, variant=variant)
        except HframeIdError:
            continue  # another model's file, or not a parameter file
        sets.append((Path(path).name, params))
    return sets


def reference_points(
    variant: str, user_points: Sequence[ParameterSet] = ()
) -> list[tuple[str, ParameterSet]]:
    """(label, parameter set) of the model's reference files (``reference_sets``) and of
    ``user_points`` (``FitOptions.known_points``)."""
    return [
        *reference_sets(variant),
        *((f"known point {i + 1} ({p.title})", p) for i, p in enumerate(user_points)),
    ]


def known_points(
    candidates: Sequence[tuple[str, ParameterSet]],
    criterion: Criterion,
    starts=None,
) -> list[KnownPoint]:
    """Each (label, parameter set) candidate with its ``criterion`` from ``starts``
    (``judged_starts``), best first."""
    points = [KnownPoint(label, params, criterion(params, starts)) for label, params in candidates]
    return sorted(points, key=lambda p: p.criterion)
