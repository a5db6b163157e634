"""Where a fit's iterations are reported (``fitting.progress``)."""

from hframe_id.fitting import FitOptions
from hframe_id.fitting.options import FitProgress
from hframe_id.fitting.progress import labelled, progress_sink

LINE = FitProgress("all windows", 3, 1234.5, 2e-3, 5e-4, "trust region shrunk")


def test_the_options_sink_wins_and_a_quiet_fit_has_none():
    sink = [].append
    assert progress_sink(FitOptions(progress=sink, verbose=2)) is sink
    assert progress_sink(FitOptions()) is None


def test_verbose_prints_one_line_per_iteration_with_the_message_at_level_2(capsys):
    progress_sink(FitOptions(verbose=1))(LINE)
    progress_sink(FitOptions(verbose=2))(LINE)
    first, second = capsys.readouterr().err.splitlines()
    assert first.split() == ["all", "windows", "it", "3", "cost", "1234.5", "step",
                             "2.0e-03", "defect", "5.0e-04"]  # fmt: skip
    assert second == first + "  trust region shrunk"


def test_labelled_prefixes_the_stage_and_leaves_none_alone():
    seen = []
    labelled(seen.append, "start 2")(LINE)
    assert seen == [FitProgress("start 2: all windows", 3, 1234.5, 2e-3, 5e-4, LINE.message)]
    assert labelled(None, "start 2") is None
