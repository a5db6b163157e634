"""From a solver's end point to the estimates (``fitting.estimates``): the box's verdict."""

import math


def test_at_a_bound_means_within_a_tenth_of_a_standard_error():
    from hframe_id.fitting.estimates import is_at_bound

    lower, upper = math.log(0.1), math.log(10.0)
    assert is_at_bound(lower, lower, upper, 1e-6)  # on it
    # 2e-4 short of it, undetermined (relative std 5): the bound, not the data, fixes it
    # (the mismatch fits that were reported converged with B_M1 there)
    assert is_at_bound(lower + 2e-4, lower, upper, 5.0)
    assert is_at_bound(upper - 0.05, lower, upper, 1.0)
    # the same distance with a well-determined estimate (std 1e-5) is an interior optimum
    assert not is_at_bound(lower + 2e-4, lower, upper, 1e-5)
    assert not is_at_bound(0.0, lower, upper, 5.0)
