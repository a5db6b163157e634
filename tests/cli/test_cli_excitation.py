"""Recordings that excite nothing (issue 27, item 3: data that cannot be fitted): where in every
recording each input holds one value and the plant stays at rest, every parameter value
simulates the same data; ``hframe-id fit`` refuses them in one ``hframe-id: error:`` line
naming the files and the inputs, exit status 2, before any fitting work, nothing written. One
such recording among others is fitted with a warning. The rule itself: ``Dataset.excites``
and ``check_excitation``."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from refusals import refused
from test_cli_hostile_files import _recording

from hframe_id.cli import main
from hframe_id.errors import FitError
from hframe_id.fitting.dataset import Dataset, check_excitation
from hframe_id.models import build_model
from hframe_id.recordings import read_recording

ROOT = Path(__file__).resolve().parents[2]
REC = ROOT / "datasets" / "4V_xmotion.mcap"
EMPS = ROOT / "datasets" / "real" / "emps-estimation.mcap"
EMPS_MODEL = ROOT / "models" / "emps_axis.py"


@pytest.fixture
def work(tmp_path, monkeypatch) -> Path:
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _held(path: Path, source: Path = REC) -> Path:
    """``source`` with every sample a copy of its first (inputs and outputs), each keeping its
    own sequence number and time: a rig that never moves, its inputs constant."""
    first: dict = {}

    def payload(i: int, message: dict) -> dict:
        if i == 0:
            first.update(message)
        return {
            **first,
            "sequence": message["sequence"],
            "device_time_us": message["device_time_us"],
        }

    return _recording(path, payload, source=source)


def test_fit_refuses_a_recording_at_rest(work, capsys):
    rec = _held(work / "rest.mcap")
    argv = ["fit", rec, "--quiet", "--no-plots", "--out-dir", "fits"]
    refused(argv, capsys, "rest.mcap", "nothing excites the model", "inputs u1, u2 constant")
    assert sorted(p.name for p in work.iterdir()) == ["rest.mcap"]


def test_fit_refuses_recordings_all_at_rest(work, capsys):
    a, b = _held(work / "a.mcap"), _held(work / "b.mcap")
    argv = ["fit", a, b, "--quiet", "--out-dir", "fits"]
    refused(argv, capsys, "a.mcap, b.mcap", "u1, u2", "every recording")
    assert sorted(p.name for p in work.iterdir()) == ["a.mcap", "b.mcap"]


def test_fit_of_a_declared_model_refuses_it_too(work, capsys):
    """The EMPS axis (``--model-file``, input ``vir``) held at its first sample: a constant
    2.5 V that friction holds, no motion."""
    rec = _held(work / "emps-rest.mcap", EMPS)
    argv = ["fit", "--model-file", EMPS_MODEL, rec, "--quiet", "--no-plots", "--out-dir", "f"]
    refused(argv, capsys, "emps-rest.mcap", "nothing excites the model", "inputs vir constant")
    assert sorted(p.name for p in work.iterdir()) == ["emps-rest.mcap"]


def test_fit_warns_of_a_recording_at_rest_among_others(work, capsys, monkeypatch):
    """Fitted with the others (the solve itself, seconds, stood in for by a refusal once the
    problem is built)."""

    def stopped(*args, **kwargs):
        raise FitError("stopped before fitting")

    monkeypatch.setattr("hframe_id.fitting.local_fit.MultipleShooting", stopped)
    rec = _held(work / "rest.mcap")
    assert main(["fit", str(rec), str(REC), "--quiet", "--no-plots", "--out-dir", "f"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines[0].startswith("hframe-id: warning: rest.mcap: inputs constant and the plant")
    assert lines[1:] == ["hframe-id: error: stopped before fitting"]


@pytest.fixture(scope="module")
def moving() -> Dataset:
    return Dataset.from_recording(build_model("hframe-8"), read_recording(REC))


def _at_rest(data: Dataset, noise: np.ndarray) -> Dataset:
    """``data`` with its inputs and outputs held at their first sample, plus ``noise``."""
    return replace(
        data,
        inputs=np.repeat(data.inputs[:1], data.n_samples, axis=0),
        measured=np.where(data.valid, data.measured[:1] + noise, np.nan),
    )


def test_the_rule_on_motion_rest_and_sensor_noise(moving):
    assert moving.excites
    still = _at_rest(moving, np.zeros_like(moving.measured))
    assert not still.excites
    # A sensor's noise at its declared level is not motion (the lasers: 5 um).
    rng = np.random.default_rng(0)
    assert not _at_rest(moving, rng.normal(size=moving.measured.shape) * moving.noise_std).excites
    # Inputs constant, the plant moving: a coast-down, or a step at the first sample.
    coasting = replace(moving, inputs=np.zeros_like(moving.inputs))
    assert coasting.excites
    # One input changing once, by one step of a 12-bit DAC, while nothing moves.
    nudged = still.inputs.copy()
    nudged[500:, 0] += 20.0 / 4096
    assert replace(still, inputs=nudged).excites


def test_check_excitation_refuses_only_when_none_excites(moving):
    still = replace(_at_rest(moving, np.zeros_like(moving.measured)), name="still.mcap")
    assert check_excitation([moving]) == ()
    assert check_excitation([still, moving]) == ("still.mcap",)
    with pytest.raises(
        FitError,
        match=r"still\.mcap, still\.mcap: nothing excites the model: "
        r"inputs u1, u2 constant .* every recording",
    ):
        check_excitation([still, still])
