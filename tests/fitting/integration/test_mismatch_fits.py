"""Whole fits on data their model did not generate: estimated noise levels, the consider
covariance of held parameters (linear and by refits), the box, and the noise rounds."""

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from hframe_id.fitting import FitOptions, StrategySettings, fit_recordings
from hframe_id.fitting.known_points import Criterion
from hframe_id.fitting.resolution import LIKELIHOOD_RATIO_95
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.simulated import simulate_recording
from hframe_id.rig.protocols import StepProtocol
from hframe_id.rig.realistic import record_realistic, shipped_plant

MODELS = Path(__file__).resolve().parents[3] / "models"


@pytest.fixture(scope="module")
def realistic_steps():
    """Two 0.6 s steps of the realistic hframe-20 plant (stick-slip with a Stribeck peak,
    current limit, actuation delay, laser latency): data the hframe-8 model cannot follow."""
    plant = shipped_plant("hframe-20")
    steps = [((-4.0, 4.0), 11), ((-4.0, -4.0), 12)]
    return [
        record_realistic(plant, StepProtocol(v, step_s=0.4, duration_s=0.6), seed=s)
        for v, s in steps
    ]


def test_mismatched_data_converge_with_estimated_noise_levels(realistic_steps):
    table = load_parameter_file(MODELS / "hframe-8-table4.2.yaml")
    options = FitOptions(free=("k_l", "k_r", "M_cart", "M_bridge", "b_cart", "b_bridge"))
    result = fit_recordings(realistic_steps, table, options)
    noise = result.diagnostics.noise
    assert result.success, result.message
    assert noise.method == "estimated" and noise.rounds >= 1
    # A real simulated trajectory: continuity defects at the solver's tolerance.
    assert result.stages[-1].max_defect <= options.defect_tol
    # The encoders see the model error far above their step (measured: ~1e3 sensor std).
    assert min(noise.channels[n].residual_rms_sensor_std for n in ("phi1", "phi2")) > 10
    for name, channel in noise.channels.items():
        # At the fixed point the residual rms is the std the fit weighed with (the iteration
        # stops once no std moves by more than ``noise_rtol`` = 5 %; the last round may move it
        # by that much again: 2x margin). Never below the sensor's own noise.
        assert channel.weight_std >= channel.sensor_std
        ratio = channel.residual_rms / channel.weight_std
        assert abs(math.log(ratio)) < 0.1, (name, ratio)


def test_matched_data_keep_the_sensor_noise_levels():
    table = load_parameter_file(MODELS / "hframe-8-table4.2.yaml")
    from hframe_id.recordings.simulated import simulate_recording

    u = np.zeros((400, 2))
    u[50:350] = (-4.0, 4.0)
    result = fit_recordings(
        [simulate_recording(table, u, seed=3)], table, FitOptions(free=("k_l", "b_bridge"))
    )
    assert result.success
    assert result.diagnostics.noise.method == "sensor"


def test_refit_consider_agrees_with_the_linear_one_where_the_effect_is_linear():
    """consider_method="refit" (whole refits at exp(+/-sigma) of each held value) against
    the tangent at the optimum, on a small matched fit: for k_l, which the held k_r moves by
    ~7 % per 20 %, nearly linearly, secant and tangent agree (measured within 7 %; 30 %
    leaves room for the curvature over +/-20 %). M_bridge barely moves (0.3 % by the tangent,
    0.02 % by the secant: its response is curved at +/-20 %, measured at +/-2 % it matches the
    tangent): both stay far below k_l's."""
    from hframe_id.recordings.simulated import simulate_recording

    table = load_parameter_file(MODELS / "hframe-8-table4.2.yaml")
    u = np.zeros((400, 2))
    u[50:350] = (-4.0, 4.0)
    recordings = [simulate_recording(table, u, seed=3)]
    added = {}
    for method in ("linear", "refit"):
        options = FitOptions(
            free=("k_l", "M_bridge"), consider={"k_r": 0.2}, consider_method=method
        )
        result = fit_recordings(recordings, table, options)
        assert result.success, result.message
        assert result.diagnostics.consider.method == method
        # the held statement says how the prior entered (not "linearised" for refits)
        assert ("linearised" in result.held_statement()) == (method == "linear")
        added[method] = result.diagnostics.consider.relative_std_added
    assert added["refit"]["k_l"] == pytest.approx(added["linear"]["k_l"], rel=0.3)
    for method in ("linear", "refit"):
        assert 0 < added[method]["M_bridge"] < 0.1 * added[method]["k_l"], method


def test_a_fit_the_box_stops_succeeds_and_says_so():
    """A converged fit with a parameter on its bound is a success (a failure is a solver that
    did not converge): the parameter is named, flagged, and its interval ends at the bound.
    Data from b_bridge = 32.5 N s/m, fitted inside [40, 60]: the box stops it at 40."""
    table = load_parameter_file(MODELS / "hframe-8-table4.2.yaml")
    u = np.zeros((400, 2))
    u[50:350] = (-4.0, 4.0)
    start = table.replace_values(b_bridge=50.0)
    options = FitOptions(free=("k_l", "b_bridge"), bounds={"b_bridge": (40.0, 60.0)})
    result = fit_recordings([simulate_recording(table, u, seed=3)], start, options)
    est = result.estimates["b_bridge"]
    assert result.success and est.at_bound and not est.identified
    # The estimate may stop up to AT_BOUND_STD standard errors inside the bound; measured on
    # it within 1e-6. The interval starts at the bound itself (to rounding of exp(log)).
    assert est.estimate == pytest.approx(40.0, rel=1e-6)
    assert est.ci95[0] == pytest.approx(40.0, rel=1e-12) and est.ci95[1] > est.estimate
    assert "at a bound" in result.message and "b_bridge" in result.message
    assert not result.estimates["k_l"].at_bound


def test_a_fit_under_mismatch_ends_with_its_defects_at_tolerance_and_is_judged_by_its_replay():
    """Realistic one-axis plant 4 (current-limited pulses the one-axis model cannot follow):
    with estimated noise levels a stall with defects of 1.9 std was once accepted, the
    residual 3e-4 rad of a discontinuous trajectory (honest fits of such pulses end at
    0.2-3 rad); then the fit stalled, its noise rounds starting from the second state pre-pass's
    discontinuous iterate. Now the noise rounds start from the moving windows' continuous
    trajectory and converge, defects at ``defect_tol``. That continuous trajectory starts
    from estimated initial positions with the belts stretched (motor angle -1.08 rad, idler
    4.5 rad against a cart at 43 mm): the written file, replayed from rest as ``validate``
    does, was further from the data than every channel held still (concentrated criterion
    -1,314 against -1,683; from the fit's own states -3,623), and the fit failed saying so.
    Now the fit ends with a solve from the replay's rest state (``fitting.replayed_rest``):
    what it reports is what the file replays, and that explains the data (measured -2,824
    against -1,683 held still and -2,036 for Table 2.1, the best point it knew): a success
    under stated mismatch."""
    from studies.mismatch_one_axis import TABLE_2_3, plant_for, pulse_recordings

    # The idler spring k3 runs to any box here (the model wants a rigid idler under the
    # mismatch): once on the default box x/÷10, now, widened to x/÷1e4 and still on it, a
    # failure saying so. Given as the user's bound (x/÷10), the case is the one above.
    table = load_parameter_file(TABLE_2_3)
    k3 = table.values["k3"]
    options = FitOptions(bounds={"k3": (k3 / 10, k3 * 10)})
    result = fit_recordings(pulse_recordings(plant_for(4), 0), table, options)
    assert result.stages[-1].max_defect <= FitOptions().defect_tol
    assert result.stages[-1].converged, result.stages[-1].message
    assert result.diagnostics.noise.method == "estimated"
    assert result.success, result.message
    report = result.diagnostics.known_points
    assert report.fit == pytest.approx(report.replayed, abs=1e-6)
    criterion = Criterion.of(result, pulse_recordings(plant_for(4), 0))
    assert report.replayed < criterion.held("one-axis") - LIKELIHOOD_RATIO_95
    assert report.replayed < min(report.points.values()) - LIKELIHOOD_RATIO_95


@pytest.mark.slow
def test_a_stalled_moving_window_stage_is_not_taken_for_mismatch():
    """Matched one-axis data of held-study plant 4 (studies.held: the idler 15-19 %
    off Table 2.3, where the default fit holds it): the moving windows stall far from the
    data (residual rms 25 sensor std) from that start. That was taken for model mismatch: the
    fit skipped the all-window stages and the restarts, estimated noise levels 25x the
    sensors' and ended at a wrong optimum whose intervals missed J_1, B_1 and b. A stalled
    stage is no evidence of mismatch: the fit now goes on with the sensors' noise levels,
    through the restarts, and every identified interval holds the truth."""
    from studies.held import run_trial

    # Measured with the initial states estimated, as when this was written. With the records'
    # velocities held at rest (the default since 2026-11-25) plant 4 ends at another optimum,
    # of lower cost (843 against 848 chi^2/2), whose J_1, B_1 and tau_c1 intervals miss the
    # truth (-9 %, +60 %, +31 %): an open point of issue 25, not hidden by this test.
    success, covered, message = run_trial(4, initial_state="estimate")
    assert success, message
    identified = {name: holds for name, (holds, ident) in covered.items() if ident}
    assert len(identified) >= 6 and all(identified.values()), covered


# Round 1 of these steps runs out of iterations (crawling along k_l / k_r; measured since
# the records start at rest), round 2 converges: a stall in round 3 falls back on round 2.
@pytest.mark.parametrize("stalled_round", [1, 3])
def test_a_stalled_last_noise_round_is_rejected(realistic_steps, monkeypatch, stalled_round):
    """The noise rounds are a majorise-minimise iteration; a last round that stalls is
    rejected as a trust region rejects a step: the fit is the last converged round's optimum,
    marked and with its noise levels reported as not settled (realistic hframe-8 plant 1 of
    the mismatch study: round 5 of 5 stalled with defects of 0.022 std, the fit failed, round
    4 had converged). With no converged round to fall back on the fit still fails. Here the
    last round is made to stall by replacing its stage report. One fit in one box
    (``local_fit.fit_in_box``): the strategy around it would continue a failed fit from the
    points it knows, whose rounds the test does not stall."""
    from hframe_id.fitting import local_fit, noise_rounds
    from hframe_id.fitting.local_fit import fit_in_box

    real_warm_solve = noise_rounds.warm_solve
    rounds = []

    def warm_solve(run, start, label, *interrupts):
        state, gn = real_warm_solve(run, start, label, *interrupts)
        names = run.problem.model.parameter_names
        rounds.append(dict(zip(names, run.problem.parameters(state.theta), strict=True)))
        if len(rounds) == stalled_round:
            run.stages[-1] = replace(
                run.stages[-1], converged=False, message="stalled (by the test)"
            )
        return state, gn

    # The rounds alone: no last solve from the replay's rest state after them
    # (``fitting.replayed_rest``, tested in test_replayed_rest_fits.py).
    monkeypatch.setattr(local_fit, "replays_rest", lambda run: False)
    monkeypatch.setattr(noise_rounds, "warm_solve", warm_solve)
    table = load_parameter_file(MODELS / "hframe-8-table4.2.yaml")
    options = FitOptions(
        free=("k_l", "k_r", "M_cart", "M_bridge", "b_cart", "b_bridge"),
        # ``stalled_round`` rounds, every one run (no level change is within 0)
        strategy=StrategySettings(max_noise_rounds=stalled_round, noise_rtol=0.0),
    )
    result = fit_in_box(realistic_steps, table, options.for_model(table.variant))
    noise = result.diagnostics.noise
    assert len(rounds) == stalled_round and noise.rounds == stalled_round
    if stalled_round == 1:
        assert not result.success and "stalled (by the test)" in result.message
        return
    assert result.success, result.message
    assert result.stages[-1].name == noise_rounds.REJECTED_ROUND_STAGE
    assert f"noise round {stalled_round - 1}'s optimum" in result.message
    for name in result.free_names:
        assert result.parameters.values[name] == pytest.approx(
            rounds[stalled_round - 2][name], rel=1e-12
        )
    assert result.stages[-1].max_defect <= options.defect_tol
    assert noise.settling.settled is False and noise.settling.change > 0
