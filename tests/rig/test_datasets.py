"""The shipped datasets: manifest, truth files, content, and regeneration."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.reader import read_recording
from hframe_id.rig.datasets import DATASETS, TRUTHS, load_manifest, make_datasets, verify_datasets

ROOT = Path(__file__).resolve().parents[2]
DATASETS_DIR = ROOT / "datasets"
NAMES = [
    "2V_ymotion.mcap", "2V_xmotion.mcap", "4V_ymotion.mcap", "4V_xmotion.mcap",
    "6V_ymotion.mcap", "6V_xmotion.mcap", "5V_oneaxis.mcap", "10V_oneaxis.mcap",
]  # fmt: skip


def read_clean(path: Path):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a shipped file must read without any warning
        return read_recording(path)


def test_manifest_lists_every_file_with_matching_sha256():
    manifest = load_manifest(DATASETS_DIR / "manifest.yaml")
    assert [e["file"] for e in manifest["datasets"]] == NAMES
    assert verify_datasets(DATASETS_DIR) == []
    seeds = [e["seed"] for e in manifest["datasets"]]
    assert len(set(seeds)) == len(seeds)
    for entry in manifest["datasets"]:
        assert (DATASETS_DIR / entry["truth"]).exists()
        assert entry["bytes"] < 150_000  # small enough to live in git


def test_truth_files_are_the_documented_drift():
    hframe = load_parameter_file(DATASETS_DIR / "truth" / "hframe-8-rig.yaml")
    table = load_parameter_file(ROOT / "models" / "hframe-8-table4.2.yaml").values
    v = hframe.values
    for k in ("k_l", "k_r", "k_b"):
        assert v[k] == pytest.approx(0.85 * table[k], rel=1e-12)
    expected = {"M_cart": 1.1612, "M_bridge": 4.19, "F_c_bridge": 2.5, "b_bridge": 35.7625,
                "tau_cM2": 0.06, "g_1": 1.0, "g_2": 0.92}  # fmt: skip
    assert {k: v[k] for k in expected} == expected
    unchanged = set(table) - set(expected) - {"k_l", "k_r", "k_b"}
    assert {k: v[k] for k in unchanged} == {k: table[k] for k in unchanged}
    one = load_parameter_file(DATASETS_DIR / "truth" / "one-axis-rig.yaml").values
    base = load_parameter_file(ROOT / "models" / "one-axis-table2.3.yaml").values
    for k in ("k1", "k2", "k3"):
        assert one[k] == pytest.approx(0.9 * base[k], rel=1e-12)
    assert (one["b"], one["F_c"]) == (19.9945, 0.25)


@pytest.mark.parametrize("name", NAMES)
def test_each_dataset(name):
    recording = read_clean(DATASETS_DIR / name)
    spec = next(d for d in DATASETS if d.file == name)
    truth = load_parameter_file(DATASETS_DIR / TRUTHS[spec.truth].file)
    assert recording.truth is not None and recording.truth.values == truth.values
    assert recording.rig["seed"] == spec.seed and recording.rig["backend"] == "sim"
    assert not recording.aborted and recording.sequence_gaps == ()
    volts = int(name.split("V_")[0])
    if name.endswith("oneaxis.mcap"):
        assert recording.variant == "one-axis" and recording.n_samples == 600
        assert recording.inputs.max() == volts and (recording.inputs > 0).sum() == 250
        return
    assert recording.variant == "hframe-8" and recording.n_samples == 1000
    u = recording.inputs[100]
    assert u[0] == -volts and u[1] == (volts if "xmotion" in name else -volts)
    assert (recording.inputs[:50] == 0).all() and (recording.inputs[550:] == 0).all()
    # Equal voltages move y, opposite ones x (eq. 1.1): the other axis barely moves. (At 2 V
    # Coulomb friction holds the bridge nearly still, so x-motion is checked from 4 V up.)
    if volts == 2:
        return
    x, y = recording.outputs[:, 2], recording.outputs[:, 3]
    moving, still = (np.nanmax(np.abs(x)), np.nanmax(np.abs(y)))
    if "ymotion" in name:
        moving, still = still, moving
    assert moving > 5 * still


def test_some_y_motions_run_the_laser_past_its_range():
    past = {n: not read_clean(DATASETS_DIR / n).valid[:, 3].all() for n in NAMES[:6:2]}
    assert past == {"2V_ymotion.mcap": False, "4V_ymotion.mcap": True, "6V_ymotion.mcap": True}


@pytest.mark.integration
def test_regenerating_gives_the_same_recordings(tmp_path):
    only = ["2V_xmotion.mcap", "10V_oneaxis.mcap"]
    make_datasets(tmp_path, only)
    for name in only:
        made, shipped = read_clean(tmp_path / name), read_clean(DATASETS_DIR / name)
        np.testing.assert_array_equal(made.inputs, shipped.inputs)
        np.testing.assert_array_equal(made.outputs, shipped.outputs)
        np.testing.assert_array_equal(made.valid, shipped.valid)
        assert made.rig == shipped.rig
        assert made.experiment == shipped.experiment
        # README promises byte-identical regeneration (metadata key order included).
        made_bytes, shipped_bytes = (
            (tmp_path / name).read_bytes(),
            (DATASETS_DIR / name).read_bytes(),
        )
        assert made_bytes == shipped_bytes


def test_datasets_commands(capsys):
    from hframe_id.cli import main

    assert main(["datasets", "verify", "--dir", str(DATASETS_DIR)]) == 0
    assert "every file matches the manifest" in capsys.readouterr().out
    assert main(["datasets", "list"]) == 0
    assert "4V_xmotion.mcap" in capsys.readouterr().out
