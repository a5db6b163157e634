"""How far a fit's default box may open, and the box opened around where a fit ended.

The default box (``problem.default_bounds``: x/÷ the bound factor f of the start) guards the
exponential, not a statement about the rig, so it must not decide the answer (issue 25, item 4).
A fit that ends with a parameter on it gets the box opened: a nonnegative parameter (friction)
below its start makes every free nonnegative one reach 0 (``FitOptions.zero_reachable``:
friction terms trade against each other, one at a time would take a fit per term); any other
squares f, ``StrategySettings.box_widenings`` times in all (opening friction to zero does not
use one up: test plant 1034's M_cart got x/÷100, not 1e4, when it did).

:class:`BoxOpening` is that rule as a pure function of the options a fit ended in and its
result, so that the stage that opens the box inside a fit (``local_fit.OpenedBox``) and the
loop that repeats a fit which ended on it early (``fit._fit_widening``) count the same
widenings.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from hframe_id.fitting.options import FitOptions
from hframe_id.fitting.result import FitResult
from hframe_id.fitting.solver import StageReport

#: The name of the stage that records the box opened around a fit's end.
OPENED_BOX_STAGE = "the default box opened"


@dataclass(frozen=True)
class BoxOpening:
    """The box a fit began in: its bound factor (> 1) and how many times it may be squared."""

    bound_factor: float
    widenings: int

    @classmethod
    def of(cls, options: FitOptions) -> BoxOpening:
        """The opening rule of a fit that begins with ``options``."""
        return cls(options.bound_factor, options.strategy.box_widenings)

    def squarings(self, options: FitOptions) -> int:
        """How many times ``options``' bound factor is this box's squared (f, f^2, f^4: 0, 1,
        2)."""
        return round(math.log2(math.log(options.bound_factor) / math.log(self.bound_factor)))

    def opened(self, options: FitOptions, result: FitResult) -> FitOptions | None:
        """``options`` (those ``result`` was fitted with) with the box opened for the free
        parameters ``result`` ended on it with (``diagnostics.at_default_box``); None if it
        ended on none, or nothing is left to open for those it did."""
        boxed = result.diagnostics.at_default_box
        if not boxed:
            return None
        kinds = {spec.name: spec.kind for spec in result.problem.model.parameters}
        friction = [n for n in result.problem.free_names if kinds[n] == "nonnegative"]
        to_zero = [
            n
            for n in boxed
            if n in friction and result.estimates[n].estimate < result.estimates[n].initial
        ]
        square = set(boxed) - set(to_zero) and self.squarings(options) < self.widenings
        zero = tuple(dict.fromkeys(options.zero_reachable + (tuple(friction) if to_zero else ())))
        factor = options.bound_factor**2 if square else options.bound_factor
        if (factor, zero) == (options.bound_factor, options.zero_reachable):
            return None
        return replace(options, zero_reachable=zero, bound_factor=factor)


def opened_box_report(ended: FitResult, before: FitOptions, after: FitOptions) -> StageReport:
    """The stage that records a fit going on from ``ended`` in the box of ``after``, opened
    from that of ``before``: which parameters ended on it, and what opened."""
    opened = []
    if after.zero_reachable != before.zero_reachable:
        opened.append(f"friction may reach 0 ({', '.join(after.zero_reachable)})")
    if after.bound_factor != before.bound_factor:
        opened.append(f"bound factor {before.bound_factor:g} -> {after.bound_factor:g}")
    last = ended.stages[-1]
    message = (
        f"{', '.join(ended.diagnostics.at_default_box)} ended on the default box; "
        f"{'; '.join(opened)}; the fit goes on from its end"
    )
    return StageReport.verdict(OPENED_BOX_STAGE, last, message, last.cost, last.max_defect)
