"""Never worse than a point the fit knows: the final criterion at other parameter sets.

A local optimizer can stop in a poorer optimum than a point it has seen or could have seen.
Here the criterion that judges the written parameter file is evaluated at the fit and at
the points it knows (issue 25, "never worse than a point it knows"):

- the start (``FitResult.initial``),
- the equation-error estimate (``equation_error.equation_error_start``),
- the model's reference files (the declaration's reference file and every other parameter
  file of the same model beside it, e.g. Tables 4.1 and 4.2 for hframe-8),
- the sets the user names (``FitOptions.known_points``).

The criterion is what ``hframe-id validate`` reproduces: a free-run simulation of each
training recording (``validation.replay.simulate_channels``) from the fit's initial state (a
record at rest: velocities zero, positions within a sensor's resolution of the replay's
rest state; this favours the fit: a point that still beats it is better), its residuals
weighted by the sensors' noise std per channel,

    C(p) = 1/2 sum_recordings sum_channels sum_valid samples ((y - y_sim(p)) / std_j)^2,

or, where the fit estimated its noise levels (model mismatch), concentrated over them: every
point gets the levels that suit it best, C(p) = sum_j N_j / 2 ln(SSR_j(p) / N_j). Judged
under the fit's own levels, which come from its own residuals, any other point would be
judged on the fit's terms (a seeded start of the lubricated plant failed at 3.6 rad motor-angle
rms with noise levels of 1.5-2 rad, under which Table 4.2 looked 300 x worse than it).
Differences of either are likelihood-ratio statistics (``Criterion``).

Each known point enters with the fit's fixed parameters and its own values of the free ones,
clipped into the user's bounds, not into the default box drawn around the start
(``fit._known_candidates``). A point counts as better when its criterion is lower by more
than ``open_ended.LIKELIHOOD_RATIO_95`` (1.92: significant at 95 %). A fit that failed is
continued from the best point other than its start.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
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


def simulation_criterion(
    params: ParameterSet,
    recordings: Sequence[Recording],
    channel_std: dict[str, float],
    latency_samples: dict[str, int] | None = None,
    initial_states: Sequence[np.ndarray | None] | None = None,
    concentrated: bool = False,
) -> float:
    """C(p) of ``params`` on ``recordings`` (module docstring); ``channel_std`` [SI] per
    output; a channel lagging by ``latency_samples`` d is compared at sample k + d with the
    model at k; ``initial_states`` per recording (None: at rest). With ``concentrated`` the
    noise levels are not given but estimated at ``params`` itself (``channel_std`` unused):
    the concentrated criterion sum_j N_j / 2 ln(SSR_j / N_j) over channels j (N_j valid
    samples, SSR_j their sum of squared residuals), which is what a fit that estimates its
    noise levels minimises, and whose differences are likelihood-ratio statistics as
    chi^2 / 2 differences are. inf if the simulation fails or leaves the finite numbers."""
    from hframe_id.validation.replay import simulate_channels

    latency = latency_samples or {}
    starts = [None] * len(recordings) if initial_states is None else initial_states
    squares: dict[str, float] = {}
    counts: dict[str, int] = {}
    for recording, x0 in zip(recordings, starts, strict=True):
        try:
            data, simulated = simulate_channels(params, recording, x0)
        except (HframeIdError, ArithmeticError, RuntimeError):
            return math.inf
        for j, name in enumerate(data.names):
            d = int(latency.get(name, 0))
            n = data.measured.shape[0] - d
            valid = data.valid[d:, j]
            residual = (data.measured[d:, j] - simulated[:n, j])[valid]
            squares[name] = squares.get(name, 0.0) + float(residual @ residual)
            counts[name] = counts.get(name, 0) + int(valid.sum())
    if concentrated:
        total = sum(
            0.5 * counts[name] * math.log(max(squares[name], math.ulp(0.0)) / counts[name])
            for name in squares
            if counts[name]
        )
    else:
        total = sum(0.5 * squares[name] / channel_std[name] ** 2 for name in squares)
    return total if np.isfinite(total) else math.inf


@dataclass(frozen=True)
class Criterion:
    """How a fit judges a parameter set: ``simulation_criterion`` on its training
    ``recordings``, under its noise levels ``channel_std`` [SI] and latencies, concentrated
    over the noise levels where the fit estimated them (``concentrated``: every point then
    gets its own levels; judged under the fit's own, estimated from its residuals, any other
    point would be judged on the fit's terms)."""

    recordings: tuple[Recording, ...]
    channel_std: dict[str, float]
    latency_samples: dict[str, int]
    concentrated: bool

    @classmethod
    def of(cls, result, recordings: Sequence[Recording]) -> Criterion:
        """The criterion of a ``FitResult``'s written file."""
        noise = result.diagnostics.get("noise") or {}
        return cls(
            tuple(recordings),
            dict(result.diagnostics["channel_std"]),
            dict(result.options.latency_samples),
            noise.get("method") == "estimated",
        )

    def __call__(self, params: ParameterSet, initial_states=None) -> float:
        """C(params) from ``initial_states`` per recording (None: at rest)."""
        return simulation_criterion(
            params,
            self.recordings,
            self.channel_std,
            self.latency_samples,
            initial_states,
            self.concentrated,
        )

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


def known_points(
    candidates: Sequence[tuple[str, ParameterSet]],
    criterion: Criterion,
    initial_states: Sequence[np.ndarray | None] | None = None,
) -> list[KnownPoint]:
    """Each (label, parameter set) candidate with its ``criterion``, best first."""
    points = [
        KnownPoint(label, params, criterion(params, initial_states)) for label, params in candidates
    ]
    return sorted(points, key=lambda p: p.criterion)
