"""The statistical resolution of the criterion (``fitting.resolution``)."""

import math
from types import SimpleNamespace

import pytest

from hframe_id.fitting.resolution import (
    LIKELIHOOD_RATIO_95,
    likelihood_gain,
    resolution_interrupt,
)

#: A transcription of n = 1,000 residuals: rms in noise std from the cost (chi^2 / 2).
MS = SimpleNamespace(residual_rms=lambda cost: math.sqrt(2 * cost / 1000))


def test_a_fall_in_cost_is_judged_as_a_likelihood_ratio_at_the_fits_noise_level():
    """At the noise level (rms 1: cost = n/2) the ratio is the fall in cost itself; far above
    it (rms 100 under the weights: model mismatch) it is n/2 log(before/after), the fall
    relative to the residuals' own level: 1,000 of a cost of 5e6 is no evidence, 5e5 is."""
    ms = MS
    assert likelihood_gain(ms, 500.0, 497.0) == pytest.approx(3.0, rel=1e-12)
    assert likelihood_gain(ms, 5e6, 5e6 - 1e3) == pytest.approx(
        500 * math.log(5e6 / (5e6 - 1e3)), rel=1e-12
    )
    assert likelihood_gain(ms, 5e6, 5e6 - 1e3) < 0.2
    assert likelihood_gain(ms, 5e6, 4.5e6) > 50
    assert likelihood_gain(ms, 500.0, 520.0) < 0


def test_a_stage_ends_once_its_last_iterations_fall_below_the_resolution():
    """At the noise level a fall of 1.5 over the window ends the stage, 2.5 does not; at 100
    noise std (cost 5e6) a fall of 1,000 is a ratio of 0.2 and ends it, 1e5 does not; a rise
    (defects closing) never does."""
    interrupt = resolution_interrupt(MS)
    assert interrupt(SimpleNamespace(cost=500.0), 1.5).startswith("converged: ")
    assert interrupt(SimpleNamespace(cost=500.0), 2.5) is None
    assert str(LIKELIHOOD_RATIO_95) in interrupt(SimpleNamespace(cost=5e6), 1e3)
    assert interrupt(SimpleNamespace(cost=5e6), 1e5) is None
    assert interrupt(SimpleNamespace(cost=500.0), -10.0) is None
