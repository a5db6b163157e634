"""The servo study's stand-in servo, records and parsing, without fitting (the fits take 20-60 s
each; ``python -m studies.servo`` runs them)."""

import dataclasses
import math
import sys

import numpy as np
import pytest

from hframe_id.cli import main as cli_main
from hframe_id.models import build_model, load_model_file
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings import read_recording
from hframe_id.simulation.open_loop import simulate
from studies import servo as study
from studies.servo import (
    CATALOGUE,
    CATALOGUE_FILE,
    COUNTS_PER_REV,
    MODEL_FILE,
    PREROLL_S,
    SAMPLE_PERIOD_S,
    SUBSTEPS,
    Scores,
    Servo,
    declared,
    draw_servo,
    encoder_counts,
    servo_record,
    simulate_servo,
    simulation_scores,
    torque_steps,
    verdict_line,
    write_csv,
)

VALUES = {"J": 3.0e-4, "B": 1.5e-4, "tau_c": 6.0e-3, "tau_0": 2.0e-4}
SHORT_S = 3.0  # records in these tests: the pre-roll and one or two steps


@pytest.fixture(scope="module")
def rotor():
    load_model_file(MODEL_FILE)
    return build_model("rotor")


@pytest.fixture(scope="module")
def steps():
    return torque_steps(np.random.default_rng(7), round(SHORT_S / SAMPLE_PERIOD_S))


def test_catalogue_is_the_models_reference(rotor):
    catalogue = load_parameter_file(CATALOGUE_FILE, "rotor")
    assert catalogue.values == CATALOGUE
    assert [p.name for p in rotor.parameters] == list(study.FITTED)


def test_without_unmodelled_effects_the_servo_is_the_declared_model(rotor, steps):
    # Same RK4, same substeps, same smoothed friction law: only the order of the floating
    # point operations differs, so the two agree to round-off over 3000 samples.
    angles, speeds = simulate_servo(declared(VALUES), steps)
    states = simulate(
        rotor, rotor.parameter_vector(VALUES), steps[:, None], SAMPLE_PERIOD_S, n_substeps=SUBSTEPS
    )[:-1]
    assert np.abs(speeds).max() > 10.0  # the rotor turns: the check is not of a rotor at rest
    np.testing.assert_allclose(angles, states[:, 0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(speeds, states[:, 1], rtol=0, atol=1e-9)


def test_a_torque_gain_is_a_rotor_with_scaled_values(steps):
    # J w' = k tau - B w - ...  is  (J / k) w' = tau - (B / k) w - ...: to round-off.
    k = 1.04
    gained = dataclasses.replace(declared(VALUES), torque_gain=k)
    scaled = declared({name: value / k for name, value in VALUES.items()})
    np.testing.assert_allclose(
        simulate_servo(gained, steps)[0], simulate_servo(scaled, steps)[0], rtol=0, atol=1e-9
    )


def test_an_input_delay_shifts_the_commanded_torque(steps):
    delayed = dataclasses.replace(declared(VALUES), delay_samples=2)
    shifted = np.concatenate((np.zeros(2), steps[:-2]))
    np.testing.assert_array_equal(
        simulate_servo(delayed, steps)[0], simulate_servo(declared(VALUES), shifted)[0]
    )


def test_a_sticking_rotor_stays_at_rest_below_the_static_level_and_breaks_away_above():
    servo = Servo(J=2e-4, B=2e-4, tau_c=5e-3, static_ratio=1.5, sticks=True)
    below = np.full(500, 0.99 * 1.5 * 5e-3)
    angles, speeds = simulate_servo(servo, below)
    assert np.all(angles == 0.0) and np.all(speeds == 0.0)
    above = np.full(500, 1.01 * 1.5 * 5e-3)
    angles, speeds = simulate_servo(servo, above)
    assert angles[-1] > 0 and np.all(speeds[1:] > 0)


def test_a_coasting_rotor_stops_and_stays_stopped():
    servo = Servo(J=2e-4, B=2e-4, tau_c=5e-3, static_ratio=1.5, sticks=True)
    torque = np.concatenate((np.full(300, 0.02), np.zeros(1700)))
    angles, speeds = simulate_servo(servo, torque)
    stopped = np.flatnonzero(speeds[300:] == 0.0)
    assert stopped.size > 0
    first = 300 + stopped[0]
    # Coulomb friction alone stops it within w / (tau_c / J) of the torque's end.
    assert first - 300 < speeds[300] * servo.J / servo.tau_c / SAMPLE_PERIOD_S + 2
    assert np.all(speeds[first:] == 0.0) and np.all(angles[first:] == angles[first])


def test_cogging_swings_a_frictionless_rotor_about_its_detent():
    # Smooth law, no friction: the rotor oscillates about the detent, energy kept by RK4.
    servo = Servo(J=2e-4, B=0.0, tau_c=0.0, cogging_nm=1e-3, cogging_periods=8)
    angles, _ = simulate_servo(servo, np.zeros(3000), theta0=0.1)
    detent = 2 * math.pi / 8 * round(0.1 * 8 / (2 * math.pi))
    assert np.abs(angles - detent).max() == pytest.approx(abs(0.1 - detent), rel=1e-3)


def test_encoder_counts_quantize_from_zero():
    servo = Servo(J=1.0, B=0.0, tau_c=0.0, counts_per_rev=COUNTS_PER_REV)
    step = 2 * math.pi / COUNTS_PER_REV
    angles = 5.0 + np.array([0.0, 0.4, 1.0, 2.5, -0.2]) * step
    counts = encoder_counts(servo, angles)
    assert counts.dtype == np.int64
    assert np.abs(counts * step - (angles - angles[0])).max() < step


def test_servos_are_seeded_and_within_the_envelope():
    assert draw_servo(3) == draw_servo(3)
    assert draw_servo(3) != draw_servo(4)
    for seed in range(50):
        servo = draw_servo(seed)
        for name in ("J", "B", "tau_c"):
            assert 0.5 <= getattr(servo, name) / CATALOGUE[name] <= 2.0
        assert abs(servo.tau_0) <= study.OFFSET_RANGE * study.TAU_MAX
        assert 1.2 <= servo.static_ratio <= 1.8 and servo.sticks
        assert 0.96 <= servo.torque_gain <= 1.04
        assert 1 <= servo.delay_samples <= 3
        assert servo.cogging_periods in study.COGGING_PERIODS
        assert servo.counts_per_rev == COUNTS_PER_REV


def test_records_start_at_rest_and_are_seeded():
    servo = draw_servo(0)
    record = servo_record(servo, 0, 1, duration_s=SHORT_S)
    n = round(SHORT_S / SAMPLE_PERIOD_S)
    preroll = round(PREROLL_S / SAMPLE_PERIOD_S)
    assert record.time_s.shape == record.torque_nm.shape == record.counts.shape == (n,)
    assert np.all(record.torque_nm[:preroll] == 0) and np.any(record.torque_nm[preroll:] != 0)
    assert np.all(record.counts[: preroll + servo.delay_samples + 1] == 0)
    assert np.abs(record.torque_nm).max() <= study.TAU_MAX
    again = servo_record(servo, 0, 1, duration_s=SHORT_S)
    np.testing.assert_array_equal(record.counts, again.counts)
    other = servo_record(servo, 0, 2, duration_s=SHORT_S)
    assert not np.array_equal(record.torque_nm, other.torque_nm)


def test_a_record_imports_as_the_rotors_recording(tmp_path, rotor):
    record = servo_record(draw_servo(1), 1, 0, duration_s=SHORT_S)
    csv_path, out = tmp_path / "run.csv", tmp_path / "run.mcap"
    write_csv(csv_path, record)
    command = study.import_command(csv_path, out, "test record")
    assert command[:3] == [sys.executable, "-m", "hframe_id"]
    assert cli_main(command[3:]) == 0
    recording = read_recording(out)
    assert recording.variant == "rotor"
    assert recording.input_names == ("tau",) and recording.output_names == ("theta",)
    np.testing.assert_array_equal(recording.inputs[:, 0], record.torque_nm)
    np.testing.assert_allclose(recording.outputs[:, 0], record.measured_rad, rtol=0, atol=1e-12)
    step = 2 * math.pi / COUNTS_PER_REV
    assert recording.declared_noise_std("theta") == pytest.approx(step / math.sqrt(12))


def test_verdict_line_keeps_the_summary_and_the_mismatch_sentence():
    stderr = (
        "fitting rotor to 3 recording(s)\n"
        "hframe-id: warning: invalid value encountered in divide\n"
        "success: converged: parameter step 7.2e-08 <= 1e-06 (cost 30000)\n"
        "model mismatch: The model does not follow the data. The channels were weighted.\n"
    )
    assert verdict_line(stderr) == (
        "success: converged: parameter step 7.2e-08 <= 1e-06 (cost 30000) | "
        "model mismatch: The model does not follow the data"
    )
    assert verdict_line("hframe-id: fit failed: J on the box\n") == (
        "hframe-id: fit failed: J on the box"
    )


def test_simulation_scores_read_validates_json():
    document = {
        "parameter_files": [{"label": "fit.yaml"}, {"label": "rotor-catalogue.yaml"}],
        "recordings": [
            {
                "results": [
                    {"channels": [{"name": "theta", "simulation_fit_percent": 99.5,
                                   "residual_rms": 0.1}]},
                    {"channels": [{"name": "theta", "simulation_fit_percent": None,
                                   "residual_rms": 3.0}]},
                ]
            }
        ],
    }  # fmt: skip
    fit, catalogue = simulation_scores(document)
    assert fit == [Scores(99.5, 0.1)]
    assert math.isnan(catalogue[0].fit_percent) and catalogue[0].rms_rad == 3.0


def test_value_range_is_checked():
    with pytest.raises(SystemExit):
        study.main(["--work", "/nonexistent", "--value-range", "2", "1"])
