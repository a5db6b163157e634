"""The shipped H-frame datasets: the joint fit of all six recovers the sim rig's truth.

datasets/*.mcap were recorded on the sim rig from datasets/truth/hframe-8-rig.yaml (an aged
belt: k x 0.85 of Table 4.1, a heavier cart and bridge, a weaker motor 2); the fit starts
from the thesis's Table 4.2 set, so every stiffness starts 18 % off and g_2 9 % off.
Tolerance 1 % (the issue's); measured worst error 0.05 % (F_c_cart). Time is printed, not
asserted (measured 3-7 s on the shared 2-core machine).
"""

from pathlib import Path

import pytest

from hframe_id.fitting import fit_recordings
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings import read_recording

ROOT = Path(__file__).resolve().parents[3]
FILES = [f"{v}V_{m}motion.mcap" for v in (2, 4, 6) for m in ("x", "y")]


@pytest.fixture(scope="module")
def fit():
    recordings = [read_recording(ROOT / "datasets" / name) for name in FILES]
    initial = load_parameter_file(ROOT / "models" / "hframe-8-table4.2.yaml")
    return recordings[0].truth, fit_recordings(recordings, initial)


def test_joint_fit_of_the_six_files_recovers_the_rig_within_1_percent(fit):
    truth, result = fit
    print(f"six-file fit: {result.wall_time_s:.2f} s, {result.iterations} iterations")
    assert result.success, result.message
    assert not result.not_identified
    for name, est in result.estimates.items():
        if est.free:
            assert est.estimate == pytest.approx(truth.values[name], rel=0.01), name
            assert est.ci95[0] <= truth.values[name] <= est.ci95[1], name
