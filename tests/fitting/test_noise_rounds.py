"""The noise levels' reading of the residuals (``fitting.noise_rounds``), on hand-made
residuals: the rms of each channel in SI units, over all recordings and per recording,
floored at its sensor's std."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from hframe_id.fitting import noise_rounds
from hframe_id.fitting.noise_rounds import channel_rms, noise_levels, recording_rms
from hframe_id.fitting.strategy_settings import StrategySettings

#: The levels the transcription weighs each recording's channels with [SI]: two recordings
#: of two windows each (windows 0, 1 and 2, 3).
STD = np.array([[0.01, 0.001], [0.02, 0.004]])
WINDOW_RECORDING = np.array([0, 0, 1, 1])
SENSOR = np.array([0.001, 0.0005])  # the sensors' std [SI]


def _fit(errors: np.ndarray, valid: np.ndarray):
    """A transcription (weights valid / its recording's std) and a state whose residuals are
    ``errors`` [SI] (4 windows of 5 samples, channels phi1 and x)."""
    problem = SimpleNamespace(
        output_names=("phi1", "x"), recording_std=STD, experiments=(None, None)
    )
    ms = SimpleNamespace(
        weight=valid / STD[WINDOW_RECORDING][:, None, :],
        problem=problem,
        window_experiment=WINDOW_RECORDING,
        ny=2,
    )
    state = SimpleNamespace(evaluation=SimpleNamespace(residual=errors * ms.weight))
    return ms, state


def _errors(per_recording: list[tuple[float, float]]) -> np.ndarray:
    """(4, 5, 2) errors [SI]: each recording's (phi1, x) error in every sample."""
    rows = [per_recording[r] for r in WINDOW_RECORDING]
    return np.array([[row] * 5 for row in rows])


def test_channel_rms_is_in_si_units_over_the_valid_samples_of_every_recording():
    valid = np.ones((4, 5, 2))
    valid[0, :, 1] = 0.0  # invalid samples count for nothing, whatever their error
    errors = _errors([(0.02, 3e-3), (0.02, 3e-3)])
    errors[0, :, 1] = 1.0
    ms, state = _fit(errors, valid)
    assert channel_rms(ms, state.evaluation) == pytest.approx({"phi1": 0.02, "x": 3e-3})
    # Pooled: the rms over all valid samples, whatever each recording was weighed with.
    ms, state = _fit(_errors([(0.01, 3e-3), (0.03, 3e-3)]), np.ones((4, 5, 2)))
    assert channel_rms(ms, state.evaluation)["phi1"] == pytest.approx(math.sqrt(5e-4))


def test_recording_rms_is_each_recordings_own():
    valid = np.ones((4, 5, 2))
    valid[3, :, 1] = 0.0
    errors = _errors([(0.01, 1e-3), (0.03, 2e-3)])
    errors[3, :, 1] = 1.0  # not valid
    ms, state = _fit(errors, valid)
    assert recording_rms(ms, state.evaluation) == pytest.approx(
        np.array([[0.01, 1e-3], [0.03, 2e-3]])
    )


def test_the_next_levels_are_each_recordings_rms_floored_at_the_sensors():
    """phi1's errors of 0.02 and 0.04 give those; x's of 1e-4, below its sensor's 5e-4, give
    5e-4 in the first recording, and 2e-3 its own in the second."""
    errors = _errors([(0.02, 1e-4), (0.04, 2e-3)])
    ms, state = _fit(errors, np.ones((4, 5, 2)))
    assert noise_levels(ms, state, SENSOR) == pytest.approx(np.array([[0.02, 5e-4], [0.04, 2e-3]]))


def test_a_recording_without_valid_samples_of_a_channel_keeps_its_level():
    valid = np.ones((4, 5, 2))
    valid[2:, :, 1] = 0.0
    ms, state = _fit(_errors([(0.02, 3e-3), (0.02, 3e-3)]), valid)
    assert noise_levels(ms, state, SENSOR) == pytest.approx(
        np.array([[0.02, 3e-3], [0.02, STD[1, 1]]])
    )


def test_the_rounds_end_at_a_round_that_ends_against_the_stiffness_wall(monkeypatch):
    """Levels that never settle (each round halves them) and a wall reached by the end of
    round 2 (theta 2): the rounds stop there, round 2's point the fit, the levels reported
    as not settled; without the wall they run to ``max_noise_rounds``."""
    strategy = StrategySettings()
    interrupted = []

    def fit(wall_at):
        stages = []
        run = SimpleNamespace(
            options=SimpleNamespace(strategy=strategy),
            stages=stages,
            problem=SimpleNamespace(
                free=("J_M1",), output_names=("phi1",), recording_std=STD[:1, :1]
            ),
            ms=None,
            against_the_wall=lambda theta: ("J_M1",) if theta[0] >= wall_at else (),
        )
        levels = iter(0.5**k for k in range(100))
        interrupted.clear()

        def weighted(recordings, run, levels):
            run.problem.recording_std = levels
            return run

        def solve(run, state, label, estimated=False, sensor_std=None):
            interrupted.append(sensor_std is not None)
            stages.append(SimpleNamespace(converged=True))
            return SimpleNamespace(theta=state.theta + 1.0), "solver"

        monkeypatch.setattr(noise_rounds, "noise_levels", lambda *args: np.array([[next(levels)]]))
        monkeypatch.setattr(noise_rounds, "_weighted", weighted)
        monkeypatch.setattr(noise_rounds, "warm_solve", solve)
        start = SimpleNamespace(theta=np.zeros(1))
        return noise_rounds.estimate_noise(run, start, [], SENSOR[:1])

    _, state, _, rounds, settling = fit(wall_at=2.0)
    assert (rounds, state.theta[0], settling.settled) == (2, 2.0, False)
    _, state, _, rounds, _ = fit(wall_at=math.inf)
    assert rounds == strategy.max_noise_rounds == state.theta[0]
    # Every round but the last may end early for re-weighting: the last runs to its tolerance.
    assert interrupted == [True] * (rounds - 1) + [False]


def test_the_reweighting_gain_is_the_majorisers_drop_at_the_new_levels():
    """Recording 1 weighed at 0.01 rad with errors of 0.02: sum N [r^2 / (2 s^2) + ln s] drops
    by N [(r/s)^2 / 2 - 1/2 - ln(r/s)] = 10 (2 - 0.5 - ln 2); x of recording 1 (errors 1e-4,
    weighed at 1e-3, floored at 5e-4) by 10 [(0.1^2 - 0.2^2) / 2 + ln 2]; recording 2 weighed
    at its own rms: nothing."""
    errors = _errors([(0.02, 1e-4), STD[1]])
    ms, state = _fit(errors, np.ones((4, 5, 2)))
    expected = 10 * (2 - 0.5 - math.log(2)) + 10 * ((0.1**2 - 0.2**2) / 2 + math.log(2))
    gain = noise_rounds.reweighting_gain(ms, state.evaluation, SENSOR)
    assert gain == pytest.approx(expected, rel=1e-12)
    at_own = _errors([tuple(STD[0]), tuple(STD[1])])
    ms, state = _fit(at_own, np.ones((4, 5, 2)))
    assert noise_rounds.reweighting_gain(ms, state.evaluation, SENSOR) == pytest.approx(0, abs=1e-9)


def test_a_round_is_interrupted_once_its_iterations_gain_less_than_reweighting_or_resolution():
    """The gain of the first test, 14.9: a round another may follow is interrupted after
    iterations that gained less (10), not after ones that gained more (100); the last round
    (no sensor std) is not. Any round ends, converged, once its iterations gained less than
    the 1.92 of the 95 % likelihood ratio (1.0), whatever the gain."""
    ms, state = _fit(_errors([(0.02, 1e-4), STD[1]]), np.ones((4, 5, 2)))
    interrupt = noise_rounds._round_interrupt(ms, SENSOR)
    assert interrupt(state.evaluation, 10.0).startswith("re-weighted: new levels lower")
    assert interrupt(state.evaluation, 100.0) is None
    assert noise_rounds._round_interrupt(ms, None)(state.evaluation, 10.0) is None
    for sensor_std in (SENSOR, None):
        stop = noise_rounds._round_interrupt(ms, sensor_std)(state.evaluation, 1.0)
        assert stop.startswith("converged: the last iterations lowered the criterion by 1")
    ms, state = _fit(_errors([(0.0105, 1e-3), STD[1]]), np.ones((4, 5, 2)))
    assert 0 < noise_rounds.reweighting_gain(ms, state.evaluation, SENSOR) < 1.0
    assert noise_rounds._round_interrupt(ms, SENSOR)(state.evaluation, 2.0) is None


def test_iterations_over_which_the_cost_rose_end_no_round():
    """A solve from new nodes (from rest) raises its cost while its defects close: that is
    neither a crawl below the resolution nor iterations that gained less than re-weighting."""
    ms, state = _fit(_errors([(0.02, 1e-4), STD[1]]), np.ones((4, 5, 2)))
    assert noise_rounds._round_interrupt(ms, SENSOR)(state.evaluation, -2.3e4) is None
    assert noise_rounds._round_interrupt(ms, None)(state.evaluation, -1.0) is None


def test_levels_settled_after_a_reweighted_round_get_one_round_to_its_tolerance(monkeypatch):
    """Rounds that may end for re-weighting do (message ``REWEIGHTED``); once the levels no
    longer move, the fit does not end on such a round: one more, without the interrupt, then
    the rounds stop (the fit ends on a solve converged to its tolerance)."""
    strategy = StrategySettings()
    stages, interrupted = [], []
    run = SimpleNamespace(
        options=SimpleNamespace(strategy=strategy),
        stages=stages,
        problem=SimpleNamespace(free=("J_M1",), output_names=("phi1",), recording_std=STD[:1, :1]),
        ms=None,
        against_the_wall=lambda theta: (),
    )
    levels = iter([0.02, 0.01, 0.01, 0.01, 0.01])

    def weighted(recordings, run, levels):
        run.problem.recording_std = levels
        return run

    def solve(run, state, label, estimated=False, sensor_std=None):
        interrupted.append(sensor_std is not None)
        ended = f"{noise_rounds.REWEIGHTED}: ..." if sensor_std is not None else "converged"
        stages.append(SimpleNamespace(converged=True, message=ended))
        return SimpleNamespace(theta=state.theta + 1.0), "solver"

    monkeypatch.setattr(noise_rounds, "noise_levels", lambda *args: np.array([[next(levels)]]))
    monkeypatch.setattr(noise_rounds, "_weighted", weighted)
    monkeypatch.setattr(noise_rounds, "warm_solve", solve)
    start = SimpleNamespace(theta=np.zeros(1))
    _, _, _, rounds, settling = noise_rounds.estimate_noise(run, start, [], SENSOR[:1])
    # round 1 at 0.02 (re-weighted), round 2 at 0.01 (re-weighted), round 3: settled after a
    # re-weighted round, to its tolerance; then settled after a converged one: the end.
    assert interrupted == [True, True, False]
    assert rounds == 3 and settling.settled
