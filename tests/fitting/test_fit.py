"""The fit's entry point (``fitting.fit.fit_recordings``): problems refused before solving."""

import dataclasses
from pathlib import Path
from types import SimpleNamespace

import pytest

from hframe_id.errors import FitError
from hframe_id.fitting import FitOptions, fit_recordings

MODELS = Path(__file__).resolve().parents[2] / "models"


def test_fit_recordings_raises_before_solving(table, recording):
    with pytest.raises(FitError):
        fit_recordings([], table)
    with pytest.raises(FitError, match="did you mean"):
        fit_recordings([recording], table, FitOptions(free=("tau_cm1",)))


def _boxed_result(boxed, options):
    """A stand-in for ``fit_in_box``'s result: ``boxed`` on the default box; parameter
    ``b`` a friction term (nonnegative) below its start, ``m`` a mass (positive) above."""
    spec = [
        SimpleNamespace(name="b", kind="nonnegative"),
        SimpleNamespace(name="m", kind="positive"),
    ]
    estimates = {
        "b": SimpleNamespace(estimate=0.1, initial=1.0),
        "m": SimpleNamespace(estimate=9.0, initial=1.0),
    }
    return SimpleNamespace(
        diagnostics=SimpleNamespace(at_default_box=tuple(boxed)),
        problem=SimpleNamespace(model=SimpleNamespace(parameters=spec), free_names=("b", "m")),
        estimates=estimates,
        success=False,
        options=options,
    )


def test_opening_friction_to_zero_does_not_use_up_a_widening(monkeypatch):
    """Friction on its lower bound first, then a mass on the box at every factor: the mass still
    gets the factor squared ``StrategySettings.box_widenings`` times (10, 100, 1e4), and the
    fit in the last box is the answer (a failure saying the box decided)."""
    from hframe_id.fitting import fit as fit_module

    calls = []

    def fake(recordings, initial, options, box=None, screened=False):
        calls.append((options.bound_factor, options.zero_reachable))
        boxed = ("b",) if not options.zero_reachable else ("m",)
        return _boxed_result(boxed, options)

    monkeypatch.setattr(fit_module, "fit_in_box", fake)
    fit_module._fit_widening([], None, FitOptions(bound_factor=10.0))
    assert calls == [(10.0, ()), (10.0, ("b",)), (100.0, ("b",)), (1e4, ("b",))]


@dataclasses.dataclass
class _Ended:
    """A stand-in for a ``FitResult`` as ``fit._off_the_wall`` reads it."""

    parameters: object
    initial: object
    success: bool = True
    message: str = "converged"

    def started_from(self, initial):
        """``FitResult.started_from`` where the start is the same (the stubs' only case)."""
        assert initial is self.initial
        return self


def _wall_strategy(monkeypatch, table, restart_criterion, restart_at_wall):
    """``fit._off_the_wall`` with its fits and criterion stubbed: the first fit ends at
    criterion 100 with J_M1 and tau_cM1 at the wall; the restart ends at
    ``restart_criterion``, at the wall or not. Returns (first, restart, calls): the starts
    the restart was given."""
    from hframe_id.fitting import fit as fit_module

    end = table.replace_values(J_M1=1e-6, tau_cM1=0.03, k_b=9000.0)
    first = _Ended(end, table)
    restart = _Ended(table.replace_values(k_b=8500.0), table, message="restart converged")
    calls = []

    def at_the_wall(result, recordings):
        ended = result.parameters
        at = ended is first.parameters or (ended is restart.parameters and restart_at_wall)
        return ("J_M1", "tau_cM1") if at else ()

    def fit_widening(recordings, initial, options, judge=None):
        calls.append(initial)
        return restart

    def judged(results, criterion):
        scores = {"fit": 100.0, "restart": restart_criterion}
        return [SimpleNamespace(label=k, criterion=scores[k]) for k, _ in results]

    monkeypatch.setattr(fit_module, "_at_the_wall", at_the_wall)
    monkeypatch.setattr(fit_module, "_fit_widening", fit_widening)
    monkeypatch.setattr(fit_module, "judged", judged)
    monkeypatch.setattr(fit_module.Criterion, "of", classmethod(lambda cls, *a, **k: None))
    return first, restart, calls


def test_a_fit_against_the_stiffness_wall_restarts_its_wall_parameters_from_the_start(
    monkeypatch, table
):
    """The restart begins where the fit ended with only the wall's parameters back at the
    start's values; better and off the wall, it is the answer, saying so."""
    from hframe_id.fitting.fit import _off_the_wall

    first, restart, calls = _wall_strategy(monkeypatch, table, 40.0, restart_at_wall=False)
    out = _off_the_wall([], table, FitOptions().for_model(table.variant), None, first)
    (begun,) = calls
    assert begun.values["J_M1"] == table.values["J_M1"]
    assert begun.values["tau_cM1"] == table.values["tau_cM1"]
    assert begun.values["k_b"] == 9000.0  # the rest from where the fit ended
    assert out.success and out.parameters is restart.parameters
    assert "restarted with J_M1, tau_cM1 at the start's values" in out.message
    assert "criterion 40 against 100" in out.message


def test_a_fit_still_against_the_stiffness_wall_fails_saying_max_substeps_decided(
    monkeypatch, table
):
    """A restart that ends worse leaves the first fit, which is still against the wall: a
    failure naming the parameters and ``max_substeps``. A prediction-error fit is not
    restarted (no simulation criterion to judge by) and fails the same way; so does a
    better restart that ends against the wall too."""
    from hframe_id.fitting.fit import _off_the_wall

    first, _, calls = _wall_strategy(monkeypatch, table, 400.0, restart_at_wall=False)
    out = _off_the_wall([], table, FitOptions().for_model(table.variant), None, first)
    assert len(calls) == 1 and out.parameters is first.parameters
    assert not out.success
    assert out.message.startswith("max_substeps decided the answer: J_M1, tau_cM1 ended")
    assert "max_substeps 500" in out.message
    calls.clear()
    out = _off_the_wall(
        [], table, FitOptions(continuity="none").for_model(table.variant), None, first
    )
    assert calls == [] and not out.success
    first, restart, _ = _wall_strategy(monkeypatch, table, 40.0, restart_at_wall=True)
    out = _off_the_wall([], table, FitOptions().for_model(table.variant), None, first)
    assert out.parameters is restart.parameters and not out.success


def test_a_fit_off_the_stiffness_wall_is_left_as_it_is(monkeypatch, table):
    from hframe_id.fitting.fit import _off_the_wall

    first, _, calls = _wall_strategy(monkeypatch, table, 40.0, restart_at_wall=False)
    calm = _Ended(table, table)
    assert _off_the_wall([], table, FitOptions().for_model(table.variant), None, calm) is calm
    assert calls == []


def test_a_continuation_from_a_known_point_that_ends_against_the_wall_is_no_success(
    monkeypatch, table
):
    """A fit that ended worse than a known point continues from it; where that continuation
    ends against the stiffness wall it is restarted off it (``_fit_from``) and, still there,
    is a failure, so the fit fails saying it ended worse (test plant 1326 of issue 25: such
    a continuation was called a success, held out 19 x the plant's reduction)."""
    from hframe_id.fitting import fit as fit_module

    first, restart, calls = _wall_strategy(monkeypatch, table, 40.0, restart_at_wall=True)
    point = SimpleNamespace(label="known point 1", parameters=table, criterion=50.0)

    def fit_widening(recordings, initial, options, judge=None):
        calls.append(initial)
        return first if len(calls) == 1 else restart

    class Judge:
        name = "criterion"

        def __call__(self, params, starts):
            return 100.0

    monkeypatch.setattr(fit_module, "_fit_widening", fit_widening)
    monkeypatch.setattr(fit_module.Criterion, "of", classmethod(lambda cls, *a: Judge()))
    monkeypatch.setattr(fit_module, "judged_starts", lambda result: None)
    monkeypatch.setattr(fit_module, "_known_candidates", lambda *a: [])
    monkeypatch.setattr(fit_module, "known_points", lambda *a: [point])
    ended = _Ended(table.replace_values(k_b=7000.0), table)
    ended.with_diagnostics = lambda **kw: ended
    options = FitOptions().for_model(table.variant)
    out = fit_module._never_worse_than_known([], table, options, ended, None)
    assert len(calls) == 2  # the continuation, then its restart off the wall
    assert calls[0] is table and calls[1].values["J_M1"] == table.values["J_M1"]
    assert not out.success
    assert out.message.startswith("did not converge: the fit ends worse than known point 1")
    assert out.message.endswith("a fit continued from there ends at inf")


def _judged(monkeypatch, small_result, model, still, held, success=True):
    """``fit._explaining_the_data`` on a hand-made result whose replay, model unforced and
    held means score ``model``, ``still`` and ``held`` (chi^2 / 2)."""
    from hframe_id.fitting import fit as fit_module
    from hframe_id.fitting.known_points import KnownPointsReport

    class Judge:
        def __call__(self, params, starts):
            return model

        def against_unforced(self, params, starts):
            return model, still, held

    monkeypatch.setattr(fit_module.Criterion, "of", classmethod(lambda cls, *a: Judge()))
    monkeypatch.setattr(fit_module, "replayed_starts", lambda result: [None])
    report = KnownPointsReport("criterion", model, {})
    result = small_result(success=success).with_diagnostics(known_points=report)
    return fit_module._explaining_the_data([], result)


def test_a_success_must_beat_its_model_unforced_and_the_held_means(monkeypatch, small_result):
    """1.92 (the 95 % likelihood ratio) below both, or the fit fails saying which it did not
    beat: its inputs held (they drive nothing under the model), or only the held means (a
    plant friction holds nearly still: test plant 1314, 12,000 against 15,739 unforced and
    3,161 held)."""
    judged = _judged(monkeypatch, small_result, 100.0, 102.0, 102.0)
    assert judged.success and judged.message == "converged"
    assert judged.diagnostics.known_points.replayed == 100.0
    judged = _judged(monkeypatch, small_result, 100.0, 101.0, 500.0)
    assert not judged.success
    assert "no closer to them than with its inputs held at their start" in judged.message
    assert "the inputs do not drive what the outputs show" in judged.message
    judged = _judged(monkeypatch, small_result, 12000.0, 15739.0, 3161.0)
    assert not judged.success
    assert judged.message.startswith("the fitted model explains none of the data")
    assert "no closer to them than each channel held at its mean" in judged.message
    assert "closer than with its inputs held at their start (15739)" in judged.message
    assert "the records show motion this model does not reproduce" in judged.message


def test_a_failed_fit_says_it_explains_none_of_the_data_after_its_own_message(
    monkeypatch, small_result
):
    judged = _judged(monkeypatch, small_result, 100.0, 100.0, 90.0, success=False)
    assert not judged.success
    assert judged.message.startswith("converged; it explains none of the data: ")
