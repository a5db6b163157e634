"""Where a fit begins (``fitting.start_screen``): the best point it knows, by the records'
simulation from rest; the start wins ties and is kept where a record starts in motion."""

import math

import pytest

from hframe_id.fitting import FitOptions
from hframe_id.fitting.known_points import simulation_criterion
from hframe_id.fitting.problem import build_problem
from hframe_id.fitting.resolution import LIKELIHOOD_RATIO_95
from hframe_id.fitting.start_screen import EQUATION_ERROR, Beginning, screen_start


def _screen(recordings, start, **options):
    return screen_start(recordings, start, FitOptions(**options).for_model(start.variant))


def test_a_fit_begins_from_the_best_point_it_knows(table, steps):
    # Masses, inertias and k_b off: Table 4.2 (near the plant) simulates the records better.
    start = table.replace_values(
        J_M1=2 * table.values["J_M1"], M_cart=2 * table.values["M_cart"], k_b=3e4
    )
    screen = _screen(steps, start, first_stage=False)
    assert list(screen.criteria) == [
        "the start",
        "hframe-8-table4.1.yaml",
        "hframe-8-table4.2.yaml",
    ]
    assert screen.label == "hframe-8-table4.2.yaml"
    assert screen.moved
    assert screen.parameters.values == table.values  # the file's values, bit for bit
    best = min(screen.criteria.values())
    assert screen.criteria[screen.label] == best
    assert best < screen.criteria["the start"] - LIKELIHOOD_RATIO_95
    # The judge: each record simulated from rest, concentrated over the noise levels,
    # floored at the sensors' std.
    problem = build_problem(steps, start, FitOptions().for_model(start.variant))
    std = dict(zip(problem.output_names, problem.channel_std, strict=True))
    assert screen.criteria["the start"] == pytest.approx(
        simulation_criterion(start, steps, std, {}, None, concentrated=True), rel=1e-12
    )
    assert "began from hframe-8-table4.2.yaml" in screen.statement()


def test_the_equation_error_estimate_is_judged_with_the_others(table, steps):
    screen = _screen(steps, table.replace_values(M_cart=2 * table.values["M_cart"]))
    assert EQUATION_ERROR in screen.criteria
    assert [label for label, _ in screen.candidates] == list(screen.criteria)


def test_the_start_wins_ties_and_equal_sets_are_judged_once(table, steps):
    screen = _screen(steps, table, first_stage=False)  # Table 4.2 itself
    assert screen.label == "the start"
    assert not screen.moved
    assert screen.parameters is table
    assert list(screen.criteria) == ["the start", "hframe-8-table4.1.yaml"]


def test_no_screen_where_a_record_starts_in_motion_or_it_is_off(table, steps, in_motion):
    start = table.replace_values(M_cart=2 * table.values["M_cart"])
    moving = [in_motion(steps[0]), steps[1]]
    screen = _screen(moving, start)
    assert (screen.label, screen.criteria, screen.candidates) == ("the start", {}, ())
    assert screen.skipped == "a record starts in motion"
    assert _screen(steps, start, screen_start=False).skipped == "off"
    assert _screen(steps, start, continuity="none").skipped == "a prediction-error fit"


def test_a_widened_fit_begins_from_a_box_end_only_if_it_is_judged_better(table):
    """``Beginning.or_better``: a point where a fit ended on its box replaces the beginning
    only when better by more than ``LIKELIHOOD_RATIO_95``, saying so."""
    end = table.replace_values(M_cart=2 * table.values["M_cart"])
    begin = Beginning(table, 100.0)
    for criterion in (100.0, 100.0 - 0.99 * LIKELIHOOD_RATIO_95, 200.0, math.inf):
        kept = begin.or_better(end, lambda params, c=criterion: c)
        assert kept.parameters is table and kept.statement == ""
    moved = begin.or_better(end, lambda params: 90.0)
    assert moved.parameters is end and moved.criterion == 90.0
    assert "continued from where it had ended on it" in moved.statement
    assert "90 against 100" in moved.statement
    # Judged once: an unjudged beginning is judged when a box end is to be compared.
    judged = Beginning(table).or_better(end, lambda params: 100.0 if params is table else 150.0)
    assert judged.parameters is table and judged.criterion == 100.0
