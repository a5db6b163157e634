"""Unit tests of ``hframe_id.fitting.structure_choice`` (no fit: results made by hand)."""

import dataclasses
import math

import pytest

from hframe_id.errors import OptionError
from hframe_id.fitting import FitOptions
from hframe_id.fitting.structure_choice import (
    StructureChoice,
    larger_options,
    refit_setup,
    with_structure_choice,
)
from hframe_id.models import EXTENDED_VARIANTS, build_model, declaration
from hframe_id.parameters import load_parameter_file
from hframe_id.resources import models_dir

LARGER = "hframe-8-current-limit"


def _choice(**changes):
    limited = load_parameter_file(models_dir() / "hframe-8-current-limit.yaml")
    choice = StructureChoice(
        asked="hframe-8",
        larger=LARGER,
        extra="I_max",
        unit="A",
        start=limited,
        criteria={"hframe-8": -1000.0, LARGER: -1500.0},
        extra_value=7.5,
        extra_relative_std=0.01,
        larger_success=True,
        chosen=LARGER,
    )
    return dataclasses.replace(choice, **changes)


def _judged_by(monkeypatch, criteria: dict, larger_start) -> None:
    """Every file's criterion looked up by its parameter set's id in ``criteria``, and
    ``larger_start`` as step 1's start of the larger fit (no simulation)."""
    from hframe_id.fitting import structure_choice

    monkeypatch.setattr(
        structure_choice.Criterion, "of", lambda *a, **k: lambda p, *a, **k: criteria[id(p)]
    )
    monkeypatch.setattr(structure_choice, "replayed_starts", lambda result: None)
    monkeypatch.setattr(structure_choice, "_larger_start", lambda *a: larger_start)


def test_hframe8_nests_in_the_current_limited_variant():
    """The larger model is hframe-8 with one parameter more, I_max [A], held by default (a
    data-sheet value) and built in."""
    assert declaration("hframe-8").nests_in == LARGER
    assert LARGER in EXTENDED_VARIANTS
    names = build_model(LARGER).parameter_names
    assert names == (*build_model("hframe-8").parameter_names, "I_max")
    assert "I_max" in declaration(LARGER).fixed
    assert declaration(LARGER).nests_in is None


@pytest.mark.parametrize(
    ("changes", "begins", "says"),
    [
        ({}, "hframe-8-current-limit kept: I_max = 7.5 A", "criterion -1500 against -1000"),
        ({"chosen": "hframe-8", "larger_success": False}, "hframe-8 kept, the", "fit failed"),
        (
            {"chosen": "hframe-8", "criteria": {"hframe-8": -1000.0, LARGER: -1001.0}},
            "hframe-8 kept, hframe-8-current-limit not better",
            "95 % likelihood ratio",
        ),
        (
            {"chosen": "hframe-8", "evidence_scale": 0.001},
            "hframe-8 kept, hframe-8-current-limit not better",
            "once scaled for correlated residuals (gain x0.001: 0.5)",
        ),
        (
            {"chosen": "hframe-8", "extra_relative_std": 0.5},
            "hframe-8 kept, I_max poorly determined",
            "relative std 0.5",
        ),
        (
            {"start": None, "criteria": {}, "chosen": "hframe-8"},
            "hframe-8-current-limit not tried",
            "sensors' noise",
        ),
        ({"start": None, "chosen": "hframe-8"}, "hframe-8-current-limit not tried", "x/÷2"),
        (
            {
                "chosen": "hframe-8",
                "second_larger": math.inf,
                "second_from": "the hframe-8 fit's end",
            },
            "hframe-8 kept",
            "fitted again from the hframe-8 fit's end, which raised",
        ),
    ],
)
def test_the_statement_says_what_decided(changes, begins, says):
    """One sentence per outcome, naming the numbers that decided."""
    statement = _choice(**changes).statement()
    assert statement.startswith(begins)
    assert says in statement


def test_the_structure_option_is_checked():
    with pytest.raises(OptionError, match="structure"):
        FitOptions(structure="both")


def test_a_fit_as_given_or_of_a_model_that_nests_in_none_is_left_alone(small_result, table):
    """``structure="as-given"`` and a model without ``nests_in`` return the result itself."""
    result = small_result()
    as_given = FitOptions(structure="as-given").for_model("hframe-8")
    assert with_structure_choice([], table, as_given, result, fit=None) is result
    one_axis = load_parameter_file(models_dir() / "one-axis-table2.3.yaml")
    options = FitOptions().for_model("one-axis")
    assert with_structure_choice([], one_axis, options, result, fit=None) is result


def test_the_larger_fit_frees_the_extra_parameter_and_does_not_choose_again():
    """The larger fit: the smaller fit's free set (the model's default where none was named)
    and I_max, its structure as given, no known points of the smaller model."""
    table = load_parameter_file(models_dir() / "hframe-8-table4.2.yaml")
    options = larger_options(FitOptions(known_points=(table,)), "I_max")
    assert options.free == ("default", "I_max")
    assert options.structure == "as-given"
    assert options.known_points == ()
    named = larger_options(FitOptions(free=("k_l", "k_r")), "I_max")
    assert named.free == ("k_l", "k_r", "I_max")


def test_folds_refit_the_structure_kept(small_result, table):
    """Cross-validation folds fit what the fit kept: the larger model from its start with
    I_max free, or the start's model, neither choosing again."""
    kept = small_result().with_diagnostics(structure=_choice())
    start, options = refit_setup(kept, table, FitOptions())
    assert start.variant == LARGER
    assert "I_max" in options.free and options.structure == "as-given"
    smaller = small_result().with_diagnostics(structure=_choice(chosen="hframe-8"))
    start, options = refit_setup(smaller, table, FitOptions())
    assert start is table and options.free is None and options.structure == "as-given"
    assert math.isfinite(_choice().extra_value)


@pytest.mark.parametrize(
    ("nests_in", "says"),
    [("no-such-model", "no such model"), ("one-axis", "it must have exactly one parameter more")],
)
def test_a_nesting_that_cannot_be_fitted_is_refused_before_any_work(monkeypatch, nests_in, says):
    """A declared ``nests_in`` that names no model, or one that is not this one with one
    parameter more: ``FitError`` naming the declaration, before the fit (a finished fit is
    never lost to it); with the structure as given the fit goes on."""
    from hframe_id.errors import FitError
    from hframe_id.fitting.structure_choice import check_nesting
    from hframe_id.models import register, registry

    monkeypatch.setattr(registry, "_REGISTERED", dict(registry._REGISTERED))  # undone after
    name = f"hframe-8-nesting-in-{nests_in}"
    register(dataclasses.replace(declaration("hframe-8"), name=name, nests_in=nests_in))
    with pytest.raises(FitError, match=f"nests_in '{nests_in}': {says}"):
        check_nesting(name, FitOptions())
    check_nesting(name, FitOptions(structure="as-given"))


def test_a_larger_fit_that_raises_leaves_the_finished_fit_standing(monkeypatch, small_result):
    """The hframe-8 fit is finished when the larger one starts: if that one raises, the
    hframe-8 fit is kept, saying why (nothing finished is lost, no traceback)."""
    from hframe_id.fitting import structure_choice
    from hframe_id.fitting.noise_rounds import NoiseReport

    table = load_parameter_file(models_dir() / "hframe-8-table4.2.yaml")
    limited = load_parameter_file(models_dir() / "hframe-8-current-limit.yaml")
    result = small_result().with_diagnostics(noise=NoiseReport(rounds=2, channels={}))
    monkeypatch.setattr(structure_choice.Criterion, "of", lambda *a, **k: lambda *a, **k: 0.0)
    monkeypatch.setattr(structure_choice, "replayed_starts", lambda result: None)
    monkeypatch.setattr(structure_choice, "_larger_start", lambda *a: limited)

    def raising(recordings, start, options):
        raise RuntimeError("integrator blew up")

    options = FitOptions().for_model("hframe-8")
    kept = with_structure_choice([], table, options, result, fit=raising)
    assert kept.parameters is result.parameters and kept.success
    assert kept.diagnostics.structure.chosen == "hframe-8"
    assert kept.message.endswith(
        "hframe-8 kept: the hframe-8-current-limit fit raised RuntimeError: integrator blew up"
    )


@pytest.mark.parametrize(("again_criterion", "kept_again"), [(-1200.0, True), (-1001.0, False)])
def test_a_better_larger_fit_with_its_limit_undetermined_is_a_start_for_the_smaller(
    monkeypatch, small_result, again_criterion, kept_again
):
    """The limited fit simulates the records better (-1500 against -1000) with I_max not
    identified: hframe-8 is fitted again from its end (I_max dropped) and kept where that
    fit is better than the first by more than the likelihood ratio (-1200), reported from the
    user's start; not where it is within it (-1001)."""
    from hframe_id.fitting.noise_rounds import NoiseReport
    from hframe_id.fitting.result import ParameterEstimate

    table = load_parameter_file(models_dir() / "hframe-8-table4.2.yaml")
    limited = load_parameter_file(models_dir() / "hframe-8-current-limit.yaml")
    first = small_result().with_diagnostics(noise=NoiseReport(rounds=2, channels={}))
    idle = ParameterEstimate("I_max", "A", 8.0, 9.5, 1e24, (0.0, math.inf), False, True, 1e23)
    larger = small_result(
        parameters=limited.replace_values(k_l=11000.0, I_max=9.5),
        estimates={**first.estimates, "I_max": idle},
    )
    again = small_result(parameters=table.replace_values(k_l=11500.0))
    criteria = {id(first.parameters): -1000.0, id(larger.parameters): -1500.0}
    criteria[id(again.parameters)] = again_criterion
    _judged_by(monkeypatch, criteria, limited)
    starts = []

    def fit(recordings, start, options):
        starts.append(start)
        assert options.structure == "as-given"
        return larger if start.variant == LARGER else dataclasses.replace(again, initial=start)

    options = FitOptions().for_model("hframe-8")
    kept = with_structure_choice([], table, options, first, fit=fit)
    # I_max ended undetermined from 8 A: the limited model fitted again from 4 A (the
    # profile's lowest) first, no better here (the same end), then the continuation.
    assert starts[1].variant == LARGER and starts[1].values["I_max"] == 4.0
    assert starts[2].variant == "hframe-8" and starts[2].values["k_l"] == 11000.0
    choice = kept.diagnostics.structure
    assert choice.second_larger == -1500.0 and "fitted again from I_max 4 A" in kept.message
    assert choice.chosen == "hframe-8"
    if kept_again:
        assert kept.parameters is again.parameters and kept.initial is table
        assert choice.continued == -1200.0
        assert "fitted again from the hframe-8-current-limit fit's end" in kept.message
        assert "criterion -1200 against -1000 for the first hframe-8 fit" in kept.message
    else:
        assert kept.parameters is first.parameters and math.isnan(choice.continued)
        assert "I_max poorly determined" in kept.message


@pytest.mark.parametrize("first_start_amps", [8.0, 4.0])
def test_a_limit_that_ended_undetermined_is_fitted_again_from_the_profiles_lowest_value(
    monkeypatch, small_result, first_start_amps
):
    """The limited fit from step 1's start (I_max 8 A) ends with I_max undetermined (-1100,
    a limit that hardly binds has no gradient): fitted again from the same start with I_max
    at the profile's lowest value (4 A: the reference 8 A / 2), it finds the limit (-1500,
    identified) and is kept, saying where it started. From a start already at 4 A no
    second fit runs."""
    from hframe_id.fitting.noise_rounds import NoiseReport
    from hframe_id.fitting.result import ParameterEstimate

    table = load_parameter_file(models_dir() / "hframe-8-table4.2.yaml")
    limited = load_parameter_file(models_dir() / "hframe-8-current-limit.yaml")
    first = small_result().with_diagnostics(noise=NoiseReport(rounds=2, channels={}))
    idle = ParameterEstimate("I_max", "A", 8.0, 8.1, 1e16, (0.0, math.inf), False, True, 1e15)
    found = ParameterEstimate("I_max", "A", 4.0, 6.2, 0.007, (6.19, 6.21), True, True, 0.001)
    stuck = small_result(
        parameters=limited.replace_values(k_l=9000.0, I_max=8.1),
        estimates={**first.estimates, "I_max": idle},
    )
    binding = small_result(
        parameters=limited.replace_values(k_l=12500.0, I_max=6.2),
        estimates={**first.estimates, "I_max": found},
    )
    start = limited.replace_values(I_max=first_start_amps)
    criteria = {
        id(first.parameters): -1000.0,
        id(stuck.parameters): -1100.0,
        id(binding.parameters): -1500.0,
    }
    _judged_by(monkeypatch, criteria, start)
    starts = []

    def fit(recordings, start_, options):
        starts.append(start_)
        if start_.variant != LARGER:
            raise RuntimeError("the continuation is not what this test is about")
        return stuck if start_.values["I_max"] == 8.0 else binding

    options = FitOptions().for_model("hframe-8")
    kept = with_structure_choice([], table, options, first, fit=fit)
    choice = kept.diagnostics.structure
    if first_start_amps == 4.0:
        assert len(starts) == 1 and choice.chosen == LARGER and choice.second_from == ""
        return
    assert [s.values["I_max"] for s in starts] == [8.0, 4.0]
    assert starts[1].values["k_l"] == limited.values["k_l"]  # step 1's start otherwise
    assert choice.chosen == LARGER and kept.parameters is binding.parameters
    assert choice.first_larger == -1100.0 and choice.start is starts[1]
    assert (
        "fitted from I_max 4 A, its profile's lowest, where the first hframe-8-current-limit "
        "fit ended with I_max undetermined (-1100)" in kept.message
    )


@pytest.mark.parametrize(("second_criterion", "refitted"), [(-1500.0, True), (-800.0, False)])
def test_a_larger_fit_that_ends_worse_than_the_smaller_is_fitted_again_from_its_end(
    monkeypatch, small_result, second_criterion, refitted
):
    """The limited fit from step 1's start ends worse (-900) than the hframe-8 fit (-1000),
    whose end is a point of the limited model: it is fitted again from that end with I_max
    at the limited model's reference value, and that fit goes on to the choice where it is
    the better of the two (-1500: kept, saying so); where it is not (-800), the first stands,
    hframe-8 is kept, and the statement says the second fit ran."""
    from hframe_id.fitting.noise_rounds import NoiseReport
    from hframe_id.fitting.result import ParameterEstimate

    table = load_parameter_file(models_dir() / "hframe-8-table4.2.yaml")
    limited = load_parameter_file(models_dir() / "hframe-8-current-limit.yaml")
    first = small_result().with_diagnostics(noise=NoiseReport(rounds=2, channels={}))
    i_max = ParameterEstimate("I_max", "A", 8.0, 7.0, 0.07, (6.86, 7.14), True, True, 0.01)
    estimates = {**first.estimates, "I_max": i_max}
    worse = small_result(parameters=limited.replace_values(k_l=9000.0), estimates=estimates)
    second = small_result(parameters=limited.replace_values(k_l=12500.0), estimates=estimates)
    criteria = {
        id(first.parameters): -1000.0,
        id(worse.parameters): -900.0,
        id(second.parameters): second_criterion,
    }
    _judged_by(monkeypatch, criteria, limited)
    starts = []

    def fit(recordings, start, options):
        starts.append(start)
        assert options.structure == "as-given" and "I_max" in options.free
        return worse if start is limited else second

    options = FitOptions().for_model("hframe-8")
    kept = with_structure_choice([], table, options, first, fit=fit)
    from_end = starts[1]
    assert starts[0] is limited and from_end.variant == LARGER
    assert from_end.values["k_l"] == first.parameters.values["k_l"]  # the smaller fit's end
    assert from_end.values["I_max"] == limited.values["I_max"]  # the reference value
    choice = kept.diagnostics.structure
    if refitted:
        assert choice.chosen == LARGER and kept.parameters is second.parameters
        assert choice.start is from_end and choice.first_larger == -900.0
        assert math.isnan(choice.second_larger)
        assert choice.criteria[LARGER] == -1500.0
        assert "where the first hframe-8-current-limit fit ended worse (-900)" in kept.message
    else:
        assert choice.chosen == "hframe-8" and kept.parameters is first.parameters
        assert choice.start is limited and math.isnan(choice.first_larger)
        assert choice.second_larger == -800.0 and choice.criteria[LARGER] == -900.0
        assert "fitted again from the hframe-8 fit's end, no better (-800)" in kept.message


def _profiled(scores_by_title: dict, i_max_gain: dict):
    """A judge for ``_larger_start``: a point's score is its base's (by title) minus
    ``i_max_gain[title]`` when the limit is at the reference 8 A, and the base's score at
    every other I_max (a limit that binds only at 8 A), no simulation."""

    def judge(params):
        base = params.title.split(",")[0]
        score = scores_by_title[base]
        if params.values.get("I_max") == 8.0:
            score -= i_max_gain[base]
        return score

    return judge


def _bases(*titles):
    table = load_parameter_file(models_dir() / "hframe-8-table4.2.yaml")
    return [
        dataclasses.replace(table.replace_values(k_l=table.values["k_l"] * (1 + k)), title=t)
        for k, t in enumerate(titles)
    ]


@pytest.mark.parametrize(
    ("scores", "gains", "chosen"),
    [
        # the limit gains nothing at the start, 5 at Table 4.1: the larger fit begins there
        ((0, 0), (0, 5), "table 4.1"),
        # both gain; Table 4.1 better by less than 1.92: the start wins the tie
        ((0, -1), (1, 1), "start"),
        # ... and by more: Table 4.1
        ((0, -3), (1, 1), "table 4.1"),
        # a base better but where the limit gains nothing is not a start of the larger fit
        ((0, -50), (1, 0), "start"),
        # no base gains: no larger fit
        ((0, 0), (0, 0), None),
    ],
)
def test_the_extra_parameter_is_profiled_at_the_start_and_the_screens_other_points(
    scores, gains, chosen
):
    """Step 1: the user's start wins unless another base is better by the likelihood ratio;
    a base where the limit gains nothing is never chosen; none gains: no larger fit."""
    from hframe_id.fitting.structure_choice import _larger_start

    bases = _bases("start", "table 4.1")
    titles = ("start", "table 4.1")
    judge = _profiled(dict(zip(titles, scores, strict=True)), dict(zip(titles, gains, strict=True)))
    start = _larger_start(bases, LARGER, "I_max", judge)
    if chosen is None:
        assert start is None
    else:
        assert start.title.startswith(chosen) and start.values["I_max"] == 8.0
        assert start.variant == LARGER


def test_the_profile_bases_leave_out_the_equation_error_estimate():
    from hframe_id.fitting.start_screen import EQUATION_ERROR, ScreenedStart
    from hframe_id.fitting.structure_choice import _profile_bases

    start, regressed, table41 = _bases("start", "regressed", "table 4.1")
    assert _profile_bases(start, None) == [start]
    screen = ScreenedStart(
        "the start",
        start,
        {},
        (("the start", start), (EQUATION_ERROR, regressed), ("Table 4.1", table41)),
    )
    assert _profile_bases(start, screen) == [start, table41]
    # a screen that did not run (a record in motion) judged nothing: the start only
    assert _profile_bases(start, ScreenedStart("the start", start, {}, skipped="off")) == [start]


@pytest.mark.parametrize(
    ("gain", "kept"),
    [(3.6, "hframe-8"), (1000.0, LARGER)],
)
def test_a_gain_within_what_correlated_residuals_give_does_not_keep_the_larger_model(
    monkeypatch, small_result, gain, kept
):
    """Test plant 1294 (linear: no limit): the limited fit gained 3.6 with I_max identified
    (robust relative std 0.0065, textbook 0.00164), over the likelihood ratio 1.92 for
    independent errors but 0.23 once scaled by the textbook over robust variance; hframe-8 is
    kept (and fitted again from the limited fit's end, step 4). A gain of 1,000 (scaled 63)
    keeps the limit."""
    from hframe_id.fitting.noise_rounds import NoiseReport
    from hframe_id.fitting.result import ParameterEstimate

    table = load_parameter_file(models_dir() / "hframe-8-table4.2.yaml")
    limited = load_parameter_file(models_dir() / "hframe-8-current-limit.yaml")
    first = small_result().with_diagnostics(noise=NoiseReport(rounds=2, channels={}))
    binding = ParameterEstimate(
        "I_max", "A", 8.0, 8.6, 0.056, (8.49, 8.71), True, True, 0.0065, 0.00164
    )
    larger = small_result(
        parameters=limited.replace_values(I_max=8.6),
        estimates={**first.estimates, "I_max": binding},
    )
    again = small_result(parameters=table.replace_values(k_l=11500.0))
    criteria = {
        id(first.parameters): -1000.0,
        id(larger.parameters): -1000.0 - gain,
        id(again.parameters): -1000.0,
    }
    _judged_by(monkeypatch, criteria, limited)

    def fit(recordings, start, options):
        return larger if start.variant == LARGER else dataclasses.replace(again, initial=start)

    options = FitOptions().for_model("hframe-8")
    choice = with_structure_choice([], table, options, first, fit=fit).diagnostics.structure
    assert choice.chosen == kept
    assert choice.evidence_scale == pytest.approx((0.00164 / 0.0065) ** 2)
    assert choice.scaled_gain == pytest.approx(gain * (0.00164 / 0.0065) ** 2)


def test_the_evidence_scale_never_inflates_a_gain():
    """The textbook over robust variance, at most 1; 1 where a std is missing."""
    from hframe_id.fitting.result import ParameterEstimate
    from hframe_id.fitting.structure_choice import _evidence_scale

    def estimate(robust, textbook):
        return ParameterEstimate("I_max", "A", 8.0, 8.0, 0.1, (7.0, 9.0), True, True,
                                 robust, textbook)  # fmt: skip

    assert _evidence_scale(estimate(0.02, 0.01)) == pytest.approx(0.25)
    assert _evidence_scale(estimate(0.01, 0.02)) == 1.0
    assert _evidence_scale(estimate(0.0, 0.01)) == 1.0
    assert _evidence_scale(estimate(math.inf, 0.01)) == 1.0
    assert _evidence_scale(estimate(0.01, 0.0)) == 1.0
