"""Options (``fitting.options``): FitOptions check each link's fields through the link (with
its message) and their own, the defaults, the frozen parts each component reads and the
model's fit defaults. Each link's own checks: test_link_options.py."""

import dataclasses
from pathlib import Path

import pytest
from test_link_options import BAD_LINK_FIELDS, _link_case_id

from hframe_id.errors import OptionError
from hframe_id.fitting import FitOptions
from hframe_id.fitting.link_options import (
    ProblemOptions,
    SolverOptions,
    StatisticsOptions,
    TranscriptionOptions,
)


@pytest.mark.parametrize(
    ("link", "name", "value", "message"), BAD_LINK_FIELDS, ids=map(_link_case_id, BAD_LINK_FIELDS)
)
def test_fit_options_refuse_each_bad_field_of_a_link_with_the_links_message(
    link, name, value, message
):
    with pytest.raises(OptionError) as err:
        FitOptions(**{name: value})
    assert message in str(err.value) and "\n" not in str(err.value)


def test_each_links_defaults_are_the_libraries():
    """A link built with no arguments is valid and is the part ``FitOptions()`` hands it for a
    model that declares no fit defaults (one set of defaults, not two that can drift)."""
    options = FitOptions().for_model("hframe-8")
    assert ProblemOptions() == options.problem_options
    assert TranscriptionOptions() == options.transcription_options
    assert SolverOptions() == options.solver_options
    assert StatisticsOptions() == options.statistics_options


def test_the_settings_left_to_the_model_are_those_a_model_declares():
    from hframe_id.fitting.options import LEFT_TO_MODEL
    from hframe_id.models.declaration import FIT_DEFAULT_KEYS

    assert LEFT_TO_MODEL == FIT_DEFAULT_KEYS


def test_a_link_stores_its_sequences_normalised_and_fit_options_keep_them():
    given = dict(free=["k_l", "k_*"], fix=iter(["B_1"]), smoothing=[1, 2], zero_reachable=["b"])
    part = ProblemOptions(**given)
    assert (part.free, part.fix, part.zero_reachable) == (("k_l", "k_*"), ("B_1",), ("b",))
    assert part.smoothing == (1.0, 2.0) and isinstance(part.smoothing[0], float)
    options = FitOptions(**{**given, "fix": ["B_1"]})
    assert (options.free, options.fix, options.smoothing) == (("k_l", "k_*"), ("B_1",), (1, 2))
    assert options.problem_options == part


def test_the_transcription_left_to_the_model_is_not_handed_out_unresolved():
    """Unresolved, the transcription would silently be the library's, not the model's."""
    with pytest.raises(OptionError, match="shooting_interval and continuity left to the model"):
        _ = FitOptions().transcription_options
    with pytest.raises(OptionError, match="^continuity left to the model"):
        _ = FitOptions(shooting_interval=5).transcription_options


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"smoothing_schedule": (1.0, 10.0)}, "smoothing_schedule must not increase"),
        ({"smoothing_schedule": (10.0, 2.0)}, "must end with 1"),
        ({"smoothing_schedule": ()}, "smoothing_schedule needs at least one factor"),
        ({"noise": "guess"}, "noise must be one of auto, sensor, estimate, got 'guess'"),
        ({"max_misfit": 0.0}, "max_misfit must be > 0, got 0.0"),
        ({"starts": 0}, "starts must be > 0, got 0"),
        ({"start_seed": -1}, "start_seed must be an integer >= 0, got -1"),
        ({"verbose": 3}, "verbose must be 0, 1 or 2, got 3"),
        ({"progress": "stderr"}, "progress must be callable"),
        ({"known_points": ("table.yaml",)}, "known_points must be ParameterSet objects, got str"),
    ],
)
def test_the_strategys_own_settings_are_checked_in_one_line(kwargs, message):
    with pytest.raises(OptionError) as err:
        FitOptions(**kwargs)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_each_component_reads_its_own_options():
    """The transcription and the problem builder get frozen parts of the flat FitOptions."""
    options = FitOptions(shooting_interval=25, continuity="none", bound_factor=3.0, threads=1)
    assert options.transcription_options == TranscriptionOptions(25, "none", 1.5, 500, 1)
    assert isinstance(options.problem_options, ProblemOptions)
    assert options.problem_options.bound_factor == 3.0
    assert options.solver_options.max_iterations == options.max_iterations
    assert options.statistics_options.confidence == 0.95


def test_the_library_applies_the_models_fit_defaults():
    """A fit from Python runs the transcription ``hframe-id fit`` runs (issue 26): settings
    left to the model take its declared ``fit_defaults``, else the library's."""
    from hframe_id.fitting.link_options import DEFAULT_CONTINUITY, DEFAULT_SHOOTING_INTERVAL
    from hframe_id.models.user import load_model_file

    load_model_file(Path(__file__).resolve().parents[2] / "models" / "emps_axis.py")
    emps = FitOptions().for_model("emps-axis")
    assert (emps.shooting_interval, emps.continuity) == (50, "none")
    given = FitOptions(shooting_interval=20).for_model("emps-axis")
    assert (given.shooting_interval, given.continuity) == (20, "none")
    plain = FitOptions().for_model("hframe-8")
    assert (plain.shooting_interval, plain.continuity) == (
        DEFAULT_SHOOTING_INTERVAL,
        DEFAULT_CONTINUITY,
    )


def test_the_defaults_leave_the_transcription_to_the_model_and_are_stored_normalised():
    options = FitOptions()
    assert (options.solver, options.noise, options.uncertainty) == (
        "gauss-newton",
        "auto",
        "robust",
    )
    assert (options.free, options.shooting_interval, options.continuity) == (None, None, None)
    described = options.for_model("hframe-8").describe()
    assert (described["free"], described["consider"]) == ("default", "default")
    assert (described["shooting_interval_samples"], described["continuity"]) == (10, "exact")
    # Sequences become tuples, smoothing velocities floats (frozen, hashable parts).
    given = FitOptions(free=["k_l", "k_*"], smoothing=[1, 2], smoothing_schedule=[4, 1])
    assert given.free == ("k_l", "k_*") and given.smoothing == (1.0, 2.0)
    assert given.smoothing_schedule == (4.0, 1.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        given.solver = "ipopt"
