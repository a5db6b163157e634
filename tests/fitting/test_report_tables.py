"""The fit report's sections from the fit alone (``fitting.report_tables``): groups of strongly
correlated parameters, said in words."""

from types import SimpleNamespace

import numpy as np
from correlated_results import CHAIN, correlated_result

from hframe_id.fitting.report_tables import (
    correlated_groups,
    correlation_lines,
    jackknife_sentence,
    markdown_table,
)


def test_groups_are_connected_components_strongest_first():
    groups = correlated_groups(correlated_result(CHAIN))
    assert [g for g, _ in groups] == [("k_l", "k_r", "J_M1")]
    assert groups[0][1] == 0.97


def test_a_sentence_per_group_with_design_advice_when_the_fitter_gave_any():
    lines = correlation_lines(correlated_result(CHAIN, {"J_M1": ("6V_ymotion",)}))
    text = "\n".join(lines)
    assert "combination of the parameters much better than each one" in text
    assert "- k_l [unit], k_r [unit], J_M1 [unit] (|r| up to 0.970)" in text
    assert "experiments that would separate them: 6V_ymotion" in text
    assert "B_M1" not in text


def test_uncorrelated_parameters_are_said_to_be_so():
    assert correlation_lines(correlated_result(np.eye(4))) == [
        "No two free parameters have |r| >= 0.9."
    ]


def test_a_markdown_table_has_a_header_a_rule_and_a_row_per_entry():
    assert markdown_table([("a", "b"), ("1", "2"), ("3", "4")]) == [
        "| a | b |",
        "| --- | --- |",
        "| 1 | 2 |",
        "| 3 | 4 |",
    ]


def test_the_jackknife_sentence_names_parameters_that_move_more_than_twice_their_error():
    """JACKKNIFE_RATIO 2: k_l's jackknife std 3x its std error is named with its ratio; k_r's
    1.5x is not; with none above the ratio, no sentence."""
    estimates = {
        "k_l": SimpleNamespace(std_error=10.0),
        "k_r": SimpleNamespace(std_error=10.0),
    }
    result = SimpleNamespace(estimates=estimates)
    moved = SimpleNamespace(
        spread=[
            SimpleNamespace(name="k_l", jackknife_std=30.0),
            SimpleNamespace(name="k_r", jackknife_std=15.0),
        ]
    )
    (sentence, blank) = jackknife_sentence(result, moved)
    assert "k_l (3x)" in sentence and "k_r" not in sentence and blank == ""
    still = SimpleNamespace(spread=[SimpleNamespace(name="k_l", jackknife_std=19.0)])
    assert jackknife_sentence(result, still) == []
