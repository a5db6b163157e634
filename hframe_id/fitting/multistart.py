"""A multistart portfolio: the same fit from several starts, the best answer and how many
reached it (issue 25, item 3).

A local optimizer started from one table answers for that start. The portfolio fits from the
user's start and from ``FitOptions.starts - 1`` seeded draws around it, each free parameter
scaled by a log-uniform factor in ``SPREAD`` ([1/2, 2], the spread of the issue's seeded-start
check; real parameters, offsets of either sign, keep the start's value), and keeps the best
successful fit by the criterion of its written file (``known_points.Criterion`` of the fit
from the user's start, so that every start is judged on one scale: chi^2 / 2 under the
sensors' noise, or concentrated over the noise levels where that fit estimated them). A start
reached the best optimum when its criterion is within ``open_ended.LIKELIHOOD_RATIO_95``
(1.92) of the best: a likelihood-ratio test at 95 % cannot tell the two apart. How many did
is reported: one of N says the answer depends on the start, N of N that the fit found the
same point from everywhere it looked.

The starts run one after another: each fit already spreads its shooting windows over the
machine's cores (``FitOptions.threads``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from hframe_id.fitting.known_points import Criterion, judged_starts
from hframe_id.fitting.resolution import LIKELIHOOD_RATIO_95
from hframe_id.parameters import ParameterSet

#: Log-uniform factor range of a seeded start around the user's start.
SPREAD = (0.5, 2.0)


@dataclass(frozen=True)
class StartOutcome:
    """One start of the portfolio: its label, whether the fit from it succeeded, and the
    criterion of its written file (chi^2 / 2 on the common scale; inf for a failed fit)."""

    label: str
    success: bool
    criterion: float


def seeded_starts(
    initial: ParameterSet,
    free: Sequence[str],
    kinds: dict[str, str],
    count: int,
    seed: int,
    bounds: Mapping[str, tuple[float, float]],
) -> list[tuple[str, ParameterSet]]:
    """(label, start) of the portfolio: ``initial`` first, then ``count - 1`` draws, each
    free parameter that is not ``real`` scaled by a log-uniform factor in ``SPREAD`` and
    clipped into the user's ``bounds`` [SI] where it has one; one generator seeded with
    ``seed`` for all draws."""
    rng = np.random.default_rng(seed)
    low, high = np.log(SPREAD)
    starts = [("the start", initial)]
    for k in range(1, count):
        factors = np.exp(rng.uniform(low, high, len(free)))
        values = {
            name: float(
                np.clip(initial.values[name] * factor, *bounds.get(name, (-np.inf, np.inf)))
            )
            for name, factor in zip(free, factors, strict=True)
            if kinds[name] != "real"
        }
        starts.append((f"seeded start {k} (seed {seed})", initial.replace_values(**values)))
    return starts


def judged(results: Sequence[tuple[str, object]], criterion: Criterion) -> list[StartOutcome]:
    """Each (label, ``FitResult``) judged by ``criterion`` (the first fit's), from its own
    initial states (``known_points.judged_starts``); a failed
    fit scores inf."""
    return [
        StartOutcome(
            label,
            bool(result.success),
            criterion(result.parameters, judged_starts(result)) if result.success else math.inf,
        )
        for label, result in results
    ]


def reached_best(outcomes: Sequence[StartOutcome]) -> int:
    """How many starts end within ``LIKELIHOOD_RATIO_95`` of the best criterion (0 if none
    succeeded)."""
    best = min((o.criterion for o in outcomes), default=math.inf)
    if not math.isfinite(best):
        return 0
    return sum(o.criterion <= best + LIKELIHOOD_RATIO_95 for o in outcomes)


def statement(outcomes: Sequence[StartOutcome]) -> str:
    """One line for the fit's summary: how many starts reached the best optimum."""
    best = min(outcomes, key=lambda o: o.criterion)
    return (
        f"multistart: {reached_best(outcomes)} of {len(outcomes)} starts reached the best "
        f"optimum (simulation criterion within {LIKELIHOOD_RATIO_95:.2f} of {best.criterion:.6g}, "
        f"from {best.label}); "
        + ", ".join(
            f"{o.label}: {o.criterion:.6g}" if o.success else f"{o.label}: failed" for o in outcomes
        )
    )
