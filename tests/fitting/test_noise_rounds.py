"""The noise levels' reading of the residuals (``fitting.noise_rounds``), on hand-made
residuals: the rms of each channel in SI units, floored at its sensor's std."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from hframe_id.fitting import noise_rounds
from hframe_id.fitting.noise_rounds import channel_rms, noise_levels
from hframe_id.fitting.strategy_settings import StrategySettings

STD = np.array([0.01, 0.001])  # the levels the transcription weighs with [SI]
SENSOR = np.array([0.001, 0.0005])  # the sensors' std [SI]


def _fit(errors: np.ndarray, valid: np.ndarray):
    """A transcription (weights valid / std) and a state whose residuals are ``errors``."""
    ms = SimpleNamespace(
        weight=valid / STD,
        problem=SimpleNamespace(output_names=("phi1", "x"), channel_std=STD),
    )
    state = SimpleNamespace(evaluation=SimpleNamespace(residual=errors * ms.weight))
    return ms, state


def test_channel_rms_is_in_si_units_over_the_valid_samples():
    valid = np.ones((4, 5, 2))
    valid[0, :, 1] = 0.0  # invalid samples count for nothing, whatever their error
    errors = np.stack([np.full((4, 5), 0.02), np.full((4, 5), 3e-3)], axis=-1)
    errors[0, :, 1] = 1.0
    ms, state = _fit(errors, valid)
    assert channel_rms(ms, state.evaluation) == pytest.approx({"phi1": 0.02, "x": 3e-3})


def test_the_next_levels_are_the_rms_floored_at_the_sensors():
    """phi1's errors of 0.02 give 0.02; x's of 1e-4, below its sensor's 5e-4, give 5e-4."""
    valid = np.ones((4, 5, 2))
    errors = np.stack([np.full((4, 5), 0.02), np.full((4, 5), 1e-4)], axis=-1)
    ms, state = _fit(errors, valid)
    assert noise_levels(ms, state, SENSOR) == pytest.approx([0.02, 5e-4], rel=1e-12)


def test_a_channel_without_valid_samples_keeps_its_level():
    valid = np.ones((4, 5, 2))
    valid[..., 1] = 0.0
    ms, state = _fit(np.full((4, 5, 2), 0.02), valid)
    assert noise_levels(ms, state, SENSOR) == pytest.approx([0.02, STD[1]], rel=1e-12)


def test_the_rounds_end_at_a_round_that_ends_against_the_stiffness_wall(monkeypatch):
    """Levels that never settle (each round halves them) and a wall reached by the end of
    round 2 (theta 2): the rounds stop there, round 2's point the fit, the levels reported
    as not settled; without the wall they run to ``max_noise_rounds``."""
    strategy = StrategySettings()

    def fit(wall_at):
        stages = []
        run = SimpleNamespace(
            options=SimpleNamespace(strategy=strategy),
            stages=stages,
            problem=SimpleNamespace(free=("J_M1",), output_names=("phi1",), channel_std=STD[:1]),
            ms=None,
            against_the_wall=lambda theta: ("J_M1",) if theta[0] >= wall_at else (),
        )
        levels = iter(0.5**k for k in range(100))

        def weighted(recordings, run, std):
            run.problem.channel_std = std
            return run

        def solve(run, state, label):
            stages.append(SimpleNamespace(converged=True))
            return SimpleNamespace(theta=state.theta + 1.0), "solver"

        monkeypatch.setattr(noise_rounds, "noise_levels", lambda *args: np.array([next(levels)]))
        monkeypatch.setattr(noise_rounds, "_weighted", weighted)
        monkeypatch.setattr(noise_rounds, "warm_solve", solve)
        start = SimpleNamespace(theta=np.zeros(1))
        return noise_rounds.estimate_noise(run, start, [], STD[:1])

    _, state, _, rounds, settling = fit(wall_at=2.0)
    assert (rounds, state.theta[0], settling.settled) == (2, 2.0, False)
    _, state, _, rounds, _ = fit(wall_at=math.inf)
    assert rounds == strategy.max_noise_rounds == state.theta[0]
