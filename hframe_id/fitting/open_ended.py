"""A parameter on the default box that the data do not bound: a one-sided answer.

A fit whose parameter still ends on the default box after the box was widened
(``fit._fit_widening``) has one of two stories. Either the criterion keeps falling towards the
box (a poorer optimum, or data that want a value outside any sensible box): the box decided
the answer and the fit fails saying so. Or the criterion no longer changes there: the data
see no difference between the box's value and much nearer ones (a belt so stiff that the
recordings show no compliance, a mass that friction holds still), so the box decided only
the written value of a parameter that the data bound on one side alone; the predictions, the
answer the user needs, are the same either way.

The test (issue 25, item 4) moves the parameter, the others held, from its value on the box
back to the bound of the box of factor sqrt(f) (``problem.default_bounds``: ``p0 f^(+/-1/2)``
in log scale, the previous box's bound under the widening schedule f -> f^2), and compares
the fit's criterion (``known_points.Criterion``: free-run simulation of every training
record from the fit's initial states, chi^2 / 2 under the sensors' noise levels, or
concentrated over the noise levels where the fit estimated them). If it rises by less than
``LIKELIHOOD_RATIO_95 = 1.92``, half the 95 % quantile of chi^2 with one degree of freedom,
the two values are not distinguishable at 95 % by a likelihood-ratio test with the other
parameters held; freeing them could only make the rise smaller (the profile lies below the
held slice), so the test never calls a bounded parameter open-ended.

For an open-ended parameter the scan goes on, in steps of a factor f^(1/4), through the start
to the other side of the box, and the last value whose rise stays below the threshold is
stated: with the others held at their fitted values, the parameter fits as well up to there.
That is the held slice's end, narrower than the profile's (with the others free the data
would allow at least as much), so it is not a confidence bound: the interval reported is the
whole physical range (``fit._with_open_ends``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from hframe_id.fitting.known_points import Criterion, judged_starts
from hframe_id.fitting.problem import default_bounds
from hframe_id.fitting.resolution import LIKELIHOOD_RATIO_95
from hframe_id.recordings.recording import Recording

#: The scan, in exponents of the bound factor f: from the box's side (the previous box's
#: bound, f^(1/2)) through the start (f^0) to the other side's bound (f^1 there).
SCAN_EXPONENTS = (0.5, 0.25, 0.0, -0.25, -0.5, -0.75, -1.0)


@dataclass(frozen=True)
class OpenEnd:
    """A free parameter on the default box, tested for being open-ended.

    ``direction``: ``"above"`` (on the upper bound) or ``"below"``; ``nearer_value`` [SI]: the
    previous box's bound, where the test moved it; ``rise``: the criterion's increase there
    (chi^2 / 2); ``finite_end`` [SI]: the farthest value of the scan still within the
    threshold, the others held (``nearer_value`` if the test failed)."""

    name: str
    direction: str
    nearer_value: float
    rise: float
    finite_end: float

    @property
    def open(self) -> bool:
        """Whether the data bound the parameter on one side only."""
        return self.rise < LIKELIHOOD_RATIO_95

    def statement(self) -> str:
        """One clause for the fit's message."""
        if self.open:
            side = ">=" if self.direction == "above" else "<="
            return (
                f"{self.name} is not bounded {self.direction} by the data ({self.name} "
                f"{side} {self.finite_end:.4g} fits as well as the box's value, the others "
                f"held: moved back to {self.nearer_value:.4g} the criterion changes by "
                f"{self.rise:.3g}, under the {LIKELIHOOD_RATIO_95:.2f} of a 95 % "
                "likelihood-ratio test)"
            )
        return (
            f"{self.name}: the criterion rises by {self.rise:.4g} when moved back to "
            f"{self.nearer_value:.4g} (the data push it onto the box)"
        )


def open_ends(
    result,
    recordings: Sequence[Recording],
    names: Sequence[str],
) -> list[OpenEnd]:
    """The ``OpenEnd`` test of each of ``names`` (free parameters of ``result``, a
    ``FitResult``, on its default box), by the criterion of its written file
    (``known_points.Criterion``) from the fit's initial states (``known_points.judged_starts``)."""
    criterion = Criterion.of(result, recordings)
    starts = judged_starts(result)
    own = criterion(result.parameters, starts)
    return [_open_end(result, name, lambda p: criterion(p, starts) - own) for name in names]


def _open_end(result, name: str, rise) -> OpenEnd:
    """The test of one parameter; ``rise(params)``: the criterion's increase at ``params``."""
    problem = result.problem
    kind = next(spec.kind for spec in problem.model.parameters if spec.name == name)
    estimate = result.estimates[name]
    above = estimate.estimate > estimate.initial
    linear = bool(problem.linear[problem.free_names.index(name)])

    def scanned(exponent: float) -> float:
        factor = result.options.bound_factor ** abs(exponent)
        low, high = default_bounds(kind, estimate.initial, factor, linear)
        return high if (exponent > 0) == above else low

    def moved(value: float):
        return result.parameters.replace_values(**{name: value})

    nearer = scanned(SCAN_EXPONENTS[0])
    first = rise(moved(nearer))
    end = nearer
    if first < LIKELIHOOD_RATIO_95:
        for exponent in SCAN_EXPONENTS[1:]:
            value = scanned(exponent)
            if rise(moved(value)) >= LIKELIHOOD_RATIO_95:
                break
            end = value
    return OpenEnd(name, "above" if above else "below", nearer, first, end)
