"""FitOptions (``fitting.options``): every field validated with a message a user can act on,
the defaults, the frozen parts each component reads and the model's fit defaults."""

import dataclasses
from pathlib import Path

import pytest

from hframe_id.errors import OptionError
from hframe_id.fitting import FitOptions


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"shooting_interval": 0}, "shooting interval must be >= 1 sample, got 0"),
        ({"free": "k_l"}, "sequence of parameter names"),
        ({"free": ()}, "at least one"),
        ({"bounds": {"k_l": (2.0, 1.0)}}, "low < high"),
        ({"bound_factor": 1.0}, "bound_factor must be > 1"),
        ({"smoothing_schedule": (1.0, 10.0)}, "must not increase"),
        ({"smoothing_schedule": (10.0, 2.0)}, "must end with 1"),
        ({"uncertainty": "bayes"}, "uncertainty must be one of"),
        ({"confidence": 95}, "confidence must be in (0, 1)"),
        ({"channel_std": {"phi1": -1.0}}, "channel_std['phi1'] must be > 0"),
        ({"max_iterations": 0}, "max_iterations must be > 0"),
        ({"consider_method": "exact"}, "consider_method must be one of linear, refit"),
    ],
)
def test_options_validate_with_actionable_messages(kwargs, message):
    with pytest.raises(OptionError, match=None) as err:
        FitOptions(**kwargs)
    assert message in str(err.value)


def test_each_component_reads_its_own_options():
    """The transcription and the problem builder get frozen parts of the flat FitOptions."""
    from hframe_id.fitting.options import ProblemOptions, TranscriptionOptions

    options = FitOptions(shooting_interval=25, continuity="none", bound_factor=3.0, threads=1)
    assert options.transcription_options == TranscriptionOptions(25, "none", 1.5, 200, 1)
    assert isinstance(options.problem_options, ProblemOptions)
    assert options.problem_options.bound_factor == 3.0
    assert options.solver_options.max_iterations == options.max_iterations
    assert options.statistics_options.confidence == 0.95


def test_the_library_applies_the_models_fit_defaults():
    """A fit from Python runs the transcription ``hframe-id fit`` runs (issue 26): settings
    left to the model take its declared ``fit_defaults``, else the library's."""
    from hframe_id.fitting.options import DEFAULT_CONTINUITY, DEFAULT_SHOOTING_INTERVAL
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


@pytest.mark.parametrize(
    ("field", "value"), [("noise", "guess"), ("consider", {"J_2": -0.2}), ("consider", [1])]
)
def test_bad_noise_and_consider_options_are_one_line_errors(field, value):
    with pytest.raises(OptionError, match=field):
        FitOptions(**{field: value})


def test_starts_must_be_a_positive_whole_number():
    with pytest.raises(OptionError, match="starts"):
        FitOptions(starts=0)
    with pytest.raises(OptionError, match="start_seed"):
        FitOptions(start_seed=-1)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"continuity": "loose"}, "continuity must be one of exact, none, got 'loose'"),
        ({"initial_state": "zero"}, "initial_state must be one of auto, rest, estimate"),
        ({"latency_samples": {"x": 101}}, "latency_samples['x'] must be a whole number"),
        ({"substep_safety": 0.5}, "substep_safety must be >= 1, got 0.5"),
        ({"max_misfit": 0.0}, "max_misfit must be > 0, got 0.0"),
        ({"threads": 1.5}, "threads must be a whole number, got 1.5"),
        ({"verbose": 3}, "verbose must be 0, 1 or 2, got 3"),
        ({"progress": "stderr"}, "progress must be callable"),
        ({"known_points": ("table.yaml",)}, "known_points must be ParameterSet objects, got str"),
    ],
)
def test_the_settings_chosen_by_name_or_number_are_checked_in_one_line(kwargs, message):
    with pytest.raises(OptionError) as err:
        FitOptions(**kwargs)
    assert message in str(err.value) and "\n" not in str(err.value)


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
