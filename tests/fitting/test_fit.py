"""The fit's entry point (``fitting.fit.fit_recordings``): problems refused before solving."""

from pathlib import Path

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
    from types import SimpleNamespace

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
    gets the factor squared ``StrategySettings.box_widenings`` times (10, 100, 1e4), then one
    whole fit (``may_widen`` False) that is judged."""
    from hframe_id.fitting import fit as fit_module

    calls = []

    def fake(recordings, initial, options, may_widen=False, screened=False):
        calls.append((options.bound_factor, options.zero_reachable, may_widen))
        boxed = ("b",) if not options.zero_reachable else ("m",)
        return _boxed_result(boxed, options)

    monkeypatch.setattr(fit_module, "fit_in_box", fake)
    fit_module._fit_widening([], None, FitOptions(bound_factor=10.0))
    assert calls == [
        (10.0, (), True),
        (10.0, ("b",), True),
        (100.0, ("b",), True),
        (1e4, ("b",), False),
    ]
