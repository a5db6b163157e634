"""The held-parameter study's counting: which intervals each coverage line counts."""

from studies.held import coverage_counts

IDLER = ("J_2", "B_2", "tau_c2")


def test_coverage_counts_split_identified_every_interval_and_idler():
    trials = [
        {"k1": (True, True), "B_1": (False, True), "F_c": (True, False), "J_2": (True, True)},
        {"k1": (False, False), "B_2": (False, False), "tau_c2": (False, True)},
    ]
    counts = coverage_counts(trials, IDLER)
    # identified, not the idler: k1 and B_1 of the first trial
    assert counts[""] == [True, False]
    # every interval but the idler's: the poorly determined F_c and the second k1 too
    assert counts[", every interval"] == [True, False, True, False]
    # the idler's identified ones only (B_2 of the second trial is not)
    assert counts[", the idler's own"] == [True, False]
