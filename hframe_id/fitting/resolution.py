"""The statistical resolution of the fit's criterion: how much of a fall in it the data can
tell from nothing.

The criterion is chi^2 / 2 of the weighted residuals. Two points whose criteria differ by less
than ``LIKELIHOOD_RATIO_95`` (half the 95 % quantile of chi^2 with one degree of freedom) are
not told apart by a likelihood-ratio test at 95 %. Far above the noise levels the weights
assume (model mismatch), a fall is measured under a common scale of the noise estimated from
the residuals instead (``likelihood_gain``): there a fall of a few units of chi^2 / 2 in
10^4-10^5 is no evidence of a better point.

A solve that lowers the criterion by less than that over its last iterations has reached what
the data resolve (``resolution_interrupt``): the realistic one-axis pulses fitted at the
sensors' weights (residuals 8-11 sensor std) crawled on for 100-120 iterations past that
point, at 0.1-0.8 of the resolution per 10 iterations, in the all-window stage of each of
12 restarts (docs/studies/2026-11-29-the-all-window-stages-end-at-the-statistical-resolution.md).
"""

from __future__ import annotations

import math
from collections.abc import Callable

from hframe_id.fitting.shooting import Evaluation, MultipleShooting

LIKELIHOOD_RATIO_95 = 0.5 * 3.841  # chi^2_1 95 % quantile / 2 (the criterion is chi^2 / 2)


def likelihood_gain(ms: MultipleShooting, before: float, after: float) -> float:
    """The log-likelihood ratio of a fit whose cost (1/2 sum of squared weighted residuals)
    fell from ``before`` to ``after``: the fall itself under the noise levels of the
    weights, or, if smaller, n/2 log(before/after) under a common scale of the noise
    estimated from the residuals (n of them): the two agree at the noise level, and far
    above it (model mismatch) a fall of a few units is no evidence of a better mode."""
    if not after > 0:
        return before - after
    half_n = before / ms.residual_rms(before) ** 2 if before > 0 else 0.0
    return min(before - after, half_n * math.log(before / after))


def resolution_interrupt(ms: MultipleShooting) -> Callable[[Evaluation, float], str | None]:
    """A ``GaussNewton.run`` interrupt (asked with the defects at tolerance) that ends an
    exact stage, converged, once its last iterations lowered the criterion by a
    log-likelihood ratio (``likelihood_gain``) below ``LIKELIHOOD_RATIO_95``. Iterations over
    which the cost rose (defects closing) end nothing."""

    def interrupt(ev: Evaluation, decrease: float) -> str | None:
        if decrease < 0:
            return None
        gain = likelihood_gain(ms, ev.cost + decrease, ev.cost)
        if gain >= LIKELIHOOD_RATIO_95:
            return None
        return (
            f"converged: the last iterations lowered the criterion by a log-likelihood ratio "
            f"of {gain:.4g}, less than the statistical resolution {LIKELIHOOD_RATIO_95}"
        )

    return interrupt
