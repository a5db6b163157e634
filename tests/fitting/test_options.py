"""FitOptions (``fitting.options``): every field validated with a message a user can act on,
the defaults, the frozen parts each component reads and the model's fit defaults."""

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
