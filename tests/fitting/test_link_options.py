"""The options of the fitter's links (``fitting.link_options``): each link checks its own
fields on construction with one line a user can act on, keeps what it is given normalised
and frozen, and defaults to the library's. ``FitOptions`` handing the links their parts:
test_options.py (which refuses ``BAD_LINK_FIELDS`` through ``FitOptions`` too)."""

import dataclasses
import math
import os
import re

import pytest

from hframe_id.errors import OptionError
from hframe_id.fitting import solvers
from hframe_id.fitting.link_options import (
    LINK_OPTIONS,
    ProblemOptions,
    SolverOptions,
    StatisticsOptions,
    TranscriptionOptions,
    default_threads,
)

#: (link, field, bad value, the one-line message): each rule of a field the link owns.
BAD_LINK_FIELDS = [
    (ProblemOptions, "free", "k_l", "free must be a sequence of parameter names or patterns"),
    (ProblemOptions, "free", 3, "free must be a sequence of parameter names or patterns, got 3"),
    (ProblemOptions, "free", (), "free must name at least one parameter"),
    (ProblemOptions, "fix", ("k_l", ""), "fix must be a sequence of parameter names"),
    (ProblemOptions, "zero_reachable", "B_1", "zero_reachable must be a sequence of parameter"),
    (ProblemOptions, "bounds", [1, 2], "bounds must map names to (low, high), got [1, 2]"),
    (ProblemOptions, "bounds", None, "bounds must map names to (low, high), got None"),
    (ProblemOptions, "bounds", {"k_l": 1.0}, "bounds['k_l'] must be (low, high), got 1.0"),
    (ProblemOptions, "bounds", {"k_l": (1.0, math.nan)}, "bounds['k_l'] must be two numbers"),
    (ProblemOptions, "bounds", {"k_l": (2.0, 1.0)}, "bounds['k_l'] must satisfy low < high"),
    (ProblemOptions, "bound_factor", 1.0, "bound_factor must be > 1, got 1.0"),
    (ProblemOptions, "bound_factor", "10", "bound_factor must be a number, got '10'"),
    (ProblemOptions, "channel_std", 0.1, "channel_std must map output names to numbers"),
    (ProblemOptions, "channel_std", {"phi1": -1.0}, "channel_std['phi1'] must be > 0, got -1.0"),
    (ProblemOptions, "recording_std", 0.1, "recording_std must map output names to one number"),
    (ProblemOptions, "recording_std", {"x": 0.1}, "recording_std['x'] must be one number per"),
    (ProblemOptions, "recording_std", {"x": ()}, "recording_std['x'] must be one number per"),
    (ProblemOptions, "recording_std", {"x": (1.0, 0.0)}, "recording_std['x'][1] must be > 0"),
    (ProblemOptions, "latency_samples", 2, "latency_samples must map output names to samples"),
    (
        ProblemOptions,
        "latency_samples",
        {"x": 101},
        "latency_samples['x'] must be a whole number of samples in 0..100, got 101",
    ),
    (ProblemOptions, "smoothing", (1e-3,), "smoothing must be (linear m/s, angular rad/s)"),
    (ProblemOptions, "smoothing", (1e-3, 0.0), "smoothing must be > 0, got 0.0"),
    (ProblemOptions, "consider", [1], "consider must map parameter names to relative std"),
    (ProblemOptions, "consider", {"J_2": -0.2}, "consider['J_2'] must be > 0, got -0.2"),
    (
        ProblemOptions,
        "consider_method",
        "exact",
        "consider_method must be one of linear, refit, prior, got 'exact'",
    ),
    (
        ProblemOptions,
        "initial_state",
        "zero",
        "initial_state must be one of auto, rest, estimate, got 'zero'",
    ),
    (TranscriptionOptions, "shooting_interval", 0, "shooting interval must be >= 1 sample, got 0"),
    (TranscriptionOptions, "shooting_interval", 2.5, "shooting interval must be >= 1 sample"),
    (
        TranscriptionOptions,
        "continuity",
        "loose",
        "continuity must be one of exact, none, got 'loose'",
    ),
    (TranscriptionOptions, "substep_safety", 0.5, "substep_safety must be >= 1, got 0.5"),
    (
        TranscriptionOptions,
        "substep_safety",
        math.inf,
        "substep_safety must be a finite number > 0, got inf",
    ),
    (TranscriptionOptions, "max_substeps", 0, "max_substeps must be > 0, got 0"),
    (TranscriptionOptions, "threads", 1.5, "threads must be a whole number, got 1.5"),
    (SolverOptions, "solver", "newton", "solver must be one of gauss-newton, ipopt, sqpmethod"),
    (SolverOptions, "max_iterations", 0, "max_iterations must be > 0, got 0"),
    (SolverOptions, "max_iterations", None, "max_iterations must be a whole number, got None"),
    (SolverOptions, "max_iterations", True, "max_iterations must be a whole number, got True"),
    (SolverOptions, "step_tol", math.nan, "step_tol must be a finite number > 0, got nan"),
    (SolverOptions, "defect_tol", math.inf, "defect_tol must be a finite number > 0, got inf"),
    (SolverOptions, "defect_tol", "1e-2", "defect_tol must be a number, got '1e-2'"),
    (StatisticsOptions, "uncertainty", "bayes", "uncertainty must be one of robust, noise-model"),
    (StatisticsOptions, "confidence", 95, "confidence must be in (0, 1), got 95"),
    (StatisticsOptions, "identifiability_threshold", 0.0, "identifiability_threshold must be > 0"),
    (StatisticsOptions, "consider", {"J_2": 0}, "consider['J_2'] must be > 0, got 0"),
    (StatisticsOptions, "consider_method", "exact", "consider_method must be one of linear"),
]


def _link_case_id(case) -> str:
    return f"{case[0].__name__}.{case[1]}={case[2]!r}"


@pytest.mark.parametrize(
    ("link", "name", "value", "message"), BAD_LINK_FIELDS, ids=map(_link_case_id, BAD_LINK_FIELDS)
)
def test_each_link_refuses_a_bad_field_of_its_own_in_one_line(link, name, value, message):
    """A link used on its own (a test, an example, a registered solver's caller) is checked."""
    with pytest.raises(OptionError) as err:
        link(**{name: value})
    assert message in str(err.value) and "\n" not in str(err.value)


def test_a_registered_solver_is_a_known_name(monkeypatch):
    """The solver's name is checked against the registry as it is, not a fixed list."""
    with pytest.raises(OptionError, match="got 'mine'"):
        SolverOptions("mine")
    monkeypatch.setitem(solvers._REGISTERED, "mine", object())
    assert SolverOptions("mine").solver == "mine"


def test_a_long_value_is_echoed_shortened():
    with pytest.raises(OptionError) as err:
        SolverOptions(solver="x" * 10_000)
    assert len(str(err.value)) < 200


@pytest.mark.parametrize(
    ("link", "name", "value", "message"),
    [
        (
            ProblemOptions,
            "latency_samples",
            {"x": True},
            "latency_samples['x'] must be a whole number of samples in 0..100, got True",
        ),
        (ProblemOptions, "bounds", {"k_l": (False, 1.0)}, "bounds['k_l'] must be two numbers"),
        (ProblemOptions, "smoothing", (True, 1.0), "smoothing must be a number, got True"),
        (ProblemOptions, "channel_std", {"x": True}, "channel_std['x'] must be a number"),
        (TranscriptionOptions, "shooting_interval", True, "shooting interval must be >= 1 sample"),
        (TranscriptionOptions, "threads", True, "threads must be a whole number, got True"),
        (StatisticsOptions, "confidence", True, "confidence must be in (0, 1), got True"),
    ],
)
def test_a_bool_is_refused_where_a_link_wants_a_number(link, name, value, message):
    """True is the int 1 to Python; as an option value it is a mistake, never a count."""
    with pytest.raises(OptionError, match="^" + re.escape(message)):
        link(**{name: value})


def test_the_solver_links_tuning_must_be_gauss_newton_settings():
    with pytest.raises(OptionError, match="^gauss_newton must be GaussNewtonSettings, got dict$"):
        SolverOptions(gauss_newton={"merit_rho": 0.2})


def test_the_ends_of_each_range_are_accepted():
    """The limits the messages state are inclusive or exclusive as stated: 0 and 100 samples
    of latency, one sample per window, a substep safety of exactly 1."""
    problem = ProblemOptions(
        bounds={"k_l": (1, 2.5)},
        bound_factor=1.001,
        latency_samples={"x": 0, "y": 100},
        consider={"J_2": 0.2},
        consider_method="prior",
    )
    assert problem.latency_samples == {"x": 0, "y": 100} and problem.bounds["k_l"] == (1, 2.5)
    transcription = TranscriptionOptions(shooting_interval=1, substep_safety=1.0, threads=1)
    assert (transcription.shooting_interval, transcription.substep_safety) == (1, 1.0)
    assert StatisticsOptions(confidence=0.999, uncertainty="hac").confidence == 0.999


@pytest.mark.parametrize(("cores", "threads"), [(None, 1), (1, 1), (3, 3), (8, 8), (64, 8)])
def test_the_default_threads_are_the_cores_at_most_eight(monkeypatch, cores, threads):
    """``os.cpu_count()`` is None where the count cannot be told: one thread then."""
    monkeypatch.setattr(os, "cpu_count", lambda: cores)
    assert default_threads() == threads
    # Read when the options are made, not when the module was imported.
    assert TranscriptionOptions().threads == threads


@pytest.mark.parametrize("link", LINK_OPTIONS, ids=lambda link: link.__name__)
def test_each_link_is_frozen_once_checked(link):
    """Checked on construction only: a field changed afterwards would escape the checks."""
    options = link()
    first = dataclasses.fields(link)[0].name
    with pytest.raises(dataclasses.FrozenInstanceError):
        setattr(options, first, None)
