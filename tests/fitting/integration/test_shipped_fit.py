"""The shipped H-frame datasets: the joint fit of all six recovers the sim rig's truth.

datasets/*.mcap were recorded on the sim rig from datasets/truth/hframe-8-rig.yaml (an aged
belt: k x 0.85 of Table 4.1, a heavier cart and bridge, a weaker motor 2); the fit starts
from the thesis's Table 4.2 set, so every stiffness starts 18 % off and g_2 9 % off.
Tolerance 1 % (the issue's); measured worst error 0.07 % (F_c_cart). Time is printed, not
asserted (measured 3-7 s on the shared 2-core machine).
"""

from pathlib import Path

import pytest
from scipy.stats import norm

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
    free = {name: est for name, est in result.estimates.items() if est.free}
    for name, est in free.items():
        assert est.estimate == pytest.approx(truth.values[name], rel=0.01), name


def test_the_sixteen_intervals_hold_the_truth_as_a_family(fit):
    """The intervals of one data set, taken together: all 16 hold the truth with 95 % only
    at Bonferroni's width, z = 2.96 standard errors (1 - 0.05 / 16, two-sided). Each at its
    own 95 % (z = 1.96), all 16 hold it with probability 0.988^16 = 0.82 even where each
    covers as measured (0.988 of 160 intervals over ten plants, studies.recovery; that
    per-interval coverage is tests/fitting/integration/test_recovery_fit.py's check).
    Measured here: largest |z| 2.57 (tau_cM1; F_c_cart 2.48, F_c_bridge 2.50, one correlated
    direction: where Coulomb friction stops the motors, read by floor-quantized encoders),
    with every record at rest starting with unstretched belts; 1.71 when every initial
    position was estimated (docs/studies/2026-11-26-replayed-verdict.md)."""
    truth, result = fit
    free = {name: est for name, est in result.estimates.items() if est.free}
    family_z = norm.ppf(1 - 0.05 / (2 * len(free)))
    for name, est in free.items():
        z = (est.estimate - truth.values[name]) / est.std_error
        assert abs(z) <= family_z, (name, z)
