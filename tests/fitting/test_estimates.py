"""From a solver's end point to the estimates (``fitting.estimates``): the box's verdict."""

import math

from hframe_id.fitting.estimates import at_bound_clause, is_at_bound


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


def test_the_distance_that_counts_as_at_a_bound_is_capped_at_a_tenth():
    """Within AT_BOUND_STD (0.1) of min(relative std, 1): an undetermined parameter (std 50)
    is at the bound 0.099 inside it, not 0.101 inside."""
    lower, upper = -1.0, 1.0
    assert is_at_bound(lower + 0.099, lower, upper, 50.0)
    assert not is_at_bound(lower + 0.101, lower, upper, 50.0)
    assert is_at_bound(upper - 0.099, lower, upper, 50.0)


def test_the_message_names_the_parameters_a_bound_stopped():
    assert at_bound_clause([]) == ""
    clause = at_bound_clause(["b_bridge", "k_l"])
    assert clause.startswith("; at a bound") and clause.endswith(": b_bridge, k_l")
    assert "--bounds widens it" in clause
