"""The mismatch study's training sets (``--train``), without fitting (a fit takes minutes)."""

import pytest

from studies import mismatch
from studies.mismatch import HELD_OUT, TRAINING_SETS, plant_for, training_recordings


def test_multisine_training_set_is_the_steps_and_a_multisine_of_other_seeds():
    """Seven recordings: the six steps unchanged, then a multisine whose phase seed and sensor
    seed differ from the held-out recordings'."""
    recordings = training_recordings(plant_for(-1), 0, "multisine")
    assert len(recordings) == 7
    assert TRAINING_SETS["multisine"][:6] == TRAINING_SETS["steps"]
    assert [r.experiment["protocol"] for r in recordings] == ["step"] * 6 + ["multisine"]
    sensor_seeds = [r.rig["seed"] for r in recordings]
    assert len(set(sensor_seeds)) == 7
    assert 10_000 not in sensor_seeds  # the held-out recordings' sensor seed (noise seed 0)
    assert recordings[-1].experiment["protocol.seed"] != HELD_OUT["multisine"].seed
    assert recordings[-1].experiment["protocol.rms_V"] == HELD_OUT["multisine"].rms_v


def test_train_option_reaches_the_trials(monkeypatch, capsys):
    calls = []
    monkeypatch.setattr(mismatch, "run_trial", lambda seed, **kw: calls.append((seed, kw)))
    monkeypatch.setattr(mismatch, "_line", lambda trial: "trial")
    assert mismatch.main(["--train", "multisine", "--seeds", "-1", "3"]) == 0
    assert [(seed, kw["train"]) for seed, kw in calls] == [(-1, "multisine"), (3, "multisine")]
    calls.clear()
    mismatch.main(["--seeds", "0"])
    assert calls[0][1]["train"] == "steps"
    with pytest.raises(SystemExit):
        mismatch.main(["--train", "pulses"])
    assert "invalid choice" in capsys.readouterr().err


def test_training_criterion_prefers_the_parameters_that_made_the_data():
    """sum_j N_j log rms_j of the free-run residuals: lower for the set that generated the
    recording than for one with a belt 50 % stiffer."""
    import numpy as np

    from hframe_id.parameters import load_parameter_file
    from hframe_id.recordings.simulated import simulate_recording
    from studies.mismatch import TABLE_4_2, training_criterion

    table = load_parameter_file(TABLE_4_2)
    u = np.zeros((300, 2))
    u[50:250] = (-4.0, 4.0)
    recording = simulate_recording(table, u, seed=2)
    stiffer = table.replace_values(k_l=1.5 * table.values["k_l"])
    assert training_criterion(table, [recording]) < training_criterion(stiffer, [recording])


def test_model_file_and_initial_reach_the_trials(monkeypatch, tmp_path):
    """--model-file registers the user model; the start defaults to its reference file, and
    --initial names another; without either, Table 4.2 as before."""
    import shutil

    from hframe_id.resources import models_dir

    calls = []
    monkeypatch.setattr(mismatch, "run_trial", lambda seed, **kw: calls.append((seed, kw)))
    monkeypatch.setattr(mismatch, "_line", lambda trial: "trial")
    model = str(models_dir() / "hframe8_stribeck.py")
    reference = models_dir() / "hframe-8-stribeck.yaml"
    other = shutil.copy(reference, tmp_path / "other-start.yaml")
    assert mismatch.main(["--model-file", model, "--seeds", "0"]) == 0
    assert mismatch.main(["--model-file", model, "--initial", str(other), "--seeds", "1"]) == 0
    assert mismatch.main(["--seeds", "2"]) == 0
    assert [(seed, kw["start"].resolve()) for seed, kw in calls] == [
        (0, reference.resolve()),
        (1, other.resolve()),
        (2, mismatch.TABLE_4_2.resolve()),
    ]


def _bad_options():
    from hframe_id.resources import models_dir

    model = str(models_dir() / "hframe8_stribeck.py")
    return [
        (["--model-file", "no/such/model.py"], "argument --model-file: model file"),
        (["--initial", "no/such/start.yaml"], "--initial: "),
        (["--model-file", model, "--initial", str(mismatch.TABLE_4_2)], "is a hframe-8 file"),
    ]


@pytest.mark.parametrize(("argv", "message"), _bad_options())
def test_bad_model_file_or_initial_is_a_one_line_usage_error(argv, message, capsys):
    with pytest.raises(SystemExit) as exit_info:
        mismatch.main([*argv, "--seeds", "0"])
    assert exit_info.value.code == 2
    error = capsys.readouterr().err
    assert message in error.strip().splitlines()[-1] and "Traceback" not in error
