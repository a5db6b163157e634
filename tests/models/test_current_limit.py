"""The smooth current limit of ``hframe_id.models.common`` (hframe-8-current-limit and
models/one_axis_current_limit.py): a clip with rounded corners, where the plant
(docs/realistic-rig.md, (A1)) clips exactly."""

import casadi as ca
import numpy as np
import pytest

from hframe_id.models import common


@pytest.fixture(scope="module")
def limit():
    i = ca.SX.sym("i")
    value = common.limited_current(i, 8.0)
    return common, ca.Function("limit", [i], [value, ca.jacobian(value, i)])


def _value(limit, current):
    return float(limit[1](current)[0])


def test_a_clip_with_rounded_corners(limit):
    module, _ = limit
    width = module.CURRENT_LIMIT_WIDTH_A
    # Below the limit by 1 A: the current itself, to rounding (the correction is 2e-22 A).
    for current in (0.0, 2.8, -5.0, 7.0):
        assert _value(limit, current) == pytest.approx(current, abs=1e-15)
    # At the limit: w ln 2 below it (the corner), and odd.
    assert _value(limit, 8.0) == pytest.approx(8.0 - width * np.log(2), rel=1e-12)
    assert _value(limit, -8.0) == pytest.approx(-_value(limit, 8.0), rel=1e-15)
    # The 6 V H-frame steps ask the shipped plant's amplifiers for about 8.05 A: the plant
    # gives 8.0, the limit within 0.002 A (the former i / (1 + (i / I_max)^20)^(1/20) gave
    # 7.75 A, 3 % short).
    assert _value(limit, 8.05) == pytest.approx(8.0, abs=2e-3)
    # Far beyond: the limit, with no overflow of the exponentials.
    for current in (8.5, 14.1, 1e6, -1e6):
        assert _value(limit, current) == pytest.approx(np.sign(current) * 8.0, abs=1e-10)


def test_smooth_with_a_slope_between_one_and_zero(limit):
    _, function = limit
    currents = np.linspace(-10.0, 10.0, 4001)
    slopes = np.array([float(function(c)[1]) for c in currents])
    assert np.all((slopes >= 0) & (slopes <= 1))
    # Smooth: over a 5 mA grid the slope changes by at most a few tenths (max 0.06 at a
    # width of 20 mA: 1 / (4 w) per ampere), no jump.
    assert np.max(np.abs(np.diff(slopes))) < 0.1
    assert float(function(8.0)[1]) == pytest.approx(0.5, abs=1e-12)
