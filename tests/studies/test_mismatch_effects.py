"""The mismatch-effects study's plants and command line, without fitting (a fit takes minutes;
the measured table is in docs/studies/2026-11-24-model-mismatch-hframe-8.md)."""

import math
from dataclasses import replace

import numpy as np
import pytest

from hframe_id.recordings.simulated import simulate_recording
from hframe_id.rig.realistic import realistic_plant, record_realistic, shipped_plant
from studies import mismatch, mismatch_effects
from studies.mismatch import HELD_OUT, MismatchTrial, training_recordings
from studies.mismatch_effects import (
    at_least_as_good,
    record_smooth,
    variants,
    without_effects,
)

#: What each variant changes in the shipped plant (field: value).
EXPECTED_CHANGES = {
    "shipped": {},
    "no-stribeck": {"static_to_coulomb_ratio": 1.0},
    "no-current-limit": {"current_limit_a": math.inf},
    "no-delays": {"actuation_delay_samples": 0, "laser_latency_samples": 0},
    "constant-stiffness": {"position_dependent_stiffness": False},
}


def _fields(plant) -> dict:
    """The plant's effect settings, one flat dict."""
    return {
        "static_to_coulomb_ratio": plant.constants.static_to_coulomb_ratio,
        "current_limit_a": plant.constants.current_limit_a,
        "actuation_delay_samples": plant.actuation_delay_samples,
        "encoder_latency_samples": plant.encoder_latency_samples,
        "laser_latency_samples": plant.laser_latency_samples,
        "position_dependent_stiffness": plant.position_dependent_stiffness,
    }


@pytest.mark.parametrize("name", sorted(EXPECTED_CHANGES))
def test_a_variant_removes_only_its_effect(name):
    shipped = shipped_plant("hframe-20")
    variant = variants()[name]
    assert variant.record is record_realistic
    assert variant.plant.parameters == shipped.parameters
    expected = {**_fields(shipped), **EXPECTED_CHANGES[name]}
    assert _fields(variant.plant) == expected
    # The shipped plant has every effect, so each variant really changes something.
    assert (_fields(variant.plant) != _fields(shipped)) == bool(EXPECTED_CHANGES[name])


def test_without_effects_keeps_only_belts_and_the_stick_slip_law():
    shipped = shipped_plant("hframe-20")
    bare = without_effects(shipped)
    assert _fields(bare) == {
        "static_to_coulomb_ratio": 1.0,
        "current_limit_a": math.inf,
        "actuation_delay_samples": 0,
        "encoder_latency_samples": 0,
        "laser_latency_samples": 0,
        "position_dependent_stiffness": False,
    }
    # The stick band and the stick time constant (the Table 2.2 law) are the shipped ones.
    assert bare.constants == replace(
        shipped.constants, static_to_coulomb_ratio=1.0, current_limit_a=math.inf
    )
    assert variants()["belts-and-stick-slip"].plant == bare


def test_stick_slip_only_plant_is_the_reduction_with_no_other_effect():
    shipped = shipped_plant("hframe-20")
    plant = variants()["stick-slip-only"].plant
    assert plant.parameters == shipped.reference()
    assert plant.reference() == shipped.reference()
    assert _fields(plant) == _fields(without_effects(shipped))


def test_smooth_recorder_is_the_plain_sim_rig():
    """The belts-smooth-friction variant records with the hframe-20 model itself (tanh
    friction, constant stiffness, no delays): the plain sim rig's recording, sample for
    sample, and not the realistic rig's."""
    variant = variants()["belts-smooth-friction"]
    assert variant.record is record_smooth
    protocol = HELD_OUT["5V x step"]
    smooth = record_smooth(variant.plant, protocol, 7)
    plain = simulate_recording(variant.plant.parameters, protocol.table(1e-3), seed=7)
    np.testing.assert_array_equal(smooth.outputs, plain.outputs)
    realistic = record_realistic(variant.plant, protocol, seed=7)
    assert np.max(np.abs(smooth.outputs - realistic.outputs)) > 1e-3  # [rad or m]


def test_training_recordings_use_the_given_recorder():
    calls = []

    def recorder(plant, protocol, seed):
        calls.append(seed)
        return protocol

    protocols = training_recordings(shipped_plant("hframe-20"), 2, "steps", recorder)
    assert protocols == list(mismatch.TRAINING_SETS["steps"])
    assert calls == [2000, 2001, 2002, 2003, 2004, 2005]


def _trial(fitted: float, reference: float) -> MismatchTrial:
    channels = ("phi1", "phi2", "x", "y")
    return MismatchTrial(
        seed=-1,
        train="steps",
        success=True,
        message="converged",
        max_defect=0.0,
        wall_time_s=1.0,
        held_out_fit={h: {c: fitted for c in channels} for h in HELD_OUT},
        reference_fit={h: {c: reference for c in channels} for h in HELD_OUT},
        channel_rms={},
        estimates={},
        criterion=(-2.0, -1.0),
        at_bound=(),
        model_reference_fit=None,
        model_reference_criterion=None,
    )


def test_at_least_as_good_counts_ties_and_wins():
    assert at_least_as_good(_trial(90.0, 90.0)) == 8
    assert at_least_as_good(_trial(89.9, 90.0)) == 0
    assert at_least_as_good(_trial(95.0, 90.0)) == 8


def test_main_runs_the_chosen_variants_with_their_recorders(monkeypatch, capsys):
    calls = []

    def fake_trial(seed, **kw):
        calls.append(kw)
        return _trial(90.0, 91.0)

    monkeypatch.setattr(mismatch_effects, "run_trial", fake_trial)
    plants = variants()
    argv = ["--variants", "no-delays", "belts-smooth-friction", "--train", "multisine"]
    assert mismatch_effects.main(argv) == 0
    assert [kw["plant"] for kw in calls] == [
        plants["no-delays"].plant,
        plants["belts-smooth-friction"].plant,
    ]
    assert [kw["record"] for kw in calls] == [record_realistic, record_smooth]
    assert {kw["train"] for kw in calls} == {"multisine"}
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("no-delays (plant -1): success=True")
    assert "fitted >= reduction in 0 of 8" in out[0]
    with pytest.raises(SystemExit):
        mismatch_effects.main(["--variants", "no-belts"])
    assert "invalid choice" in capsys.readouterr().err


def test_seeds_take_the_variants_of_fresh_plants(monkeypatch):
    """``--seeds``: each base plant (the shipped one for -1, ``realistic_plant`` otherwise) is
    varied as the shipped one is, and its trial labelled with its seed."""
    calls = []

    def fake_trial(seed, **kw):
        calls.append((seed, kw["plant"]))
        return _trial(90.0, 91.0)

    monkeypatch.setattr(mismatch_effects, "run_trial", fake_trial)
    argv = ["--variants", "shipped", "no-current-limit", "--seeds", "-1", "3"]
    assert mismatch_effects.main(argv) == 0
    fresh = realistic_plant("hframe-20", 3)
    assert calls == [
        (-1, shipped_plant("hframe-20")),
        (-1, variants()["no-current-limit"].plant),
        (3, fresh),
        (3, variants(fresh)["no-current-limit"].plant),
    ]
    assert calls[3][1].parameters == fresh.parameters
    assert calls[3][1].constants.current_limit_a == math.inf
