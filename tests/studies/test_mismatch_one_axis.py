"""The one-axis mismatch study: one trial on the shipped plant, its pulses against the shipped
datasets' protocol, and its options."""

import math

import pytest
import yaml

from hframe_id.errors import OptionError
from hframe_id.fitting import FitOptions
from hframe_id.parameters import load_parameter_file
from hframe_id.resources import datasets_dir
from studies import mismatch_one_axis
from studies.mismatch import parse_latency
from studies.mismatch_one_axis import (
    HELD_OUT,
    plant_for,
    pulse_recordings,
    run_trial,
)


def test_pulses_are_the_shipped_datasets_protocol():
    """The fitted pulses carry the protocol fields of 5V_oneaxis.mcap and 10V_oneaxis.mcap;
    the shipped plant's own parameters are datasets/realistic/truth/one-axis.yaml's."""
    realistic = datasets_dir() / "realistic"
    manifest = yaml.safe_load((realistic / "manifest.yaml").read_text())
    shipped = {e["file"]: e["protocol"] for e in manifest["datasets"]}
    recordings = pulse_recordings(plant_for(-1), 0)
    assert [r.experiment for r in recordings] == [
        shipped["5V_oneaxis.mcap"],
        shipped["10V_oneaxis.mcap"],
    ]
    assert [r.rig["seed"] for r in recordings] == [0, 1]
    assert all(r.variant == "one-axis" for r in recordings)
    # the held-out simulations' "plant" parameters: the shipped truth file's
    truth = load_parameter_file(realistic / "truth" / "one-axis.yaml")
    assert plant_for(-1).reference().values == truth.values


def test_one_trial_on_the_shipped_plant():
    """The trial's plumbing: fit, held-out records, the plant's reduction, the line. The
    study's default fit of these pulses (all nine parameters free) takes 90 s on a 2-core
    machine and ends worse than its start
    (docs/studies/2026-11-29-the-all-window-stages-end-at-the-statistical-resolution.md);
    whole one-axis fits of mismatched pulses are tested in
    tests/fitting/integration/test_mismatch_fits.py. Here two friction parameters are free,
    which every part of the trial's output covers."""
    trial = run_trial(-1, options=FitOptions(free=("b", "F_c")))
    assert trial.seed == -1 and trial.train == "pulses"
    assert isinstance(trial.success, bool) and trial.message
    assert math.isfinite(trial.max_defect) and trial.wall_time_s > 0
    assert set(trial.channel_rms) == {"phi1", "x"}
    assert set(trial.at_bound) <= set(trial.estimates)
    for fits in (trial.held_out_fit, trial.reference_fit):
        assert set(fits) == set(HELD_OUT)
        for channels in fits.values():
            assert list(channels) == ["phi1", "x"]
            assert all(math.isfinite(v) for v in channels.values())
    assert all(math.isfinite(c) for c in trial.criterion)
    assert "at_bound=[" in mismatch_one_axis._line(trial)


def test_latency_option_reaches_the_fit(monkeypatch):
    calls = []
    monkeypatch.setattr(mismatch_one_axis, "run_trial", lambda seed, **kw: calls.append((seed, kw)))
    monkeypatch.setattr(mismatch_one_axis, "_line", lambda trial: "trial")
    assert mismatch_one_axis.main(["--seeds", "-1", "4", "--latency", "phi1=1,x=3"]) == 0
    assert [seed for seed, _ in calls] == [-1, 4]
    assert all(kw["options"].latency_samples == {"phi1": 1, "x": 3} for _, kw in calls)
    calls.clear()
    mismatch_one_axis.main([])
    assert calls[0][0] == -1 and calls[0][1]["options"].latency_samples == {}


def test_parse_latency():
    assert parse_latency("") == {}
    assert parse_latency("phi1=1, x=3") == {"phi1": 1, "x": 3}
    with pytest.raises(OptionError):
        parse_latency("x=two")
    with pytest.raises(OptionError):
        parse_latency("x")
