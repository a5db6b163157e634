"""One-axis drive (thesis ch. 2): the shipped 5 V + 10 V pulses recover the sim rig's truth.

datasets/{5,10}V_oneaxis.mcap were recorded (seed 2301, encoder quantization, 5 um laser
noise, laser range +/-5 cm: the cart is seen in 30-50 % of each pulse) from
datasets/truth/one-axis-rig.yaml: Table 2.1 + 2.3 with every belt stiffness x 0.9,
b = 19.9945 (start 19.0424, 5 % off) and F_c = 0.25 (start 0.2, 20 % off). The fit starts
from models/one-axis-table2.3.yaml.

The idler pulley (phi3) is not measured: by default its J_2, B_2, tau_c2 are held at the
start's values (here equal to the truth, so this test does not measure the bias a wrong
idler value causes; docs/fitting.md does). Tolerance 2 % (issue 5's target for friction and
inertia; also applied to the stiffnesses); measured worst error 0.37 % (B_1), stiffnesses
within 0.05 %. Time printed, not asserted (measured ~5 s).
"""

from pathlib import Path

import pytest

from hframe_id.fitting import fit_recordings
from hframe_id.fitting.problem import default_free
from hframe_id.models import build_model
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings import read_recording

ROOT = Path(__file__).resolve().parents[1]
FILES = ("5V_oneaxis.mcap", "10V_oneaxis.mcap")


@pytest.fixture(scope="module")
def fit():
    recordings = [read_recording(ROOT / "datasets" / name) for name in FILES]
    initial = load_parameter_file(ROOT / "models" / "one-axis-table2.3.yaml")
    truth = load_parameter_file(ROOT / "datasets" / "truth" / "one-axis-rig.yaml")
    return truth, fit_recordings(recordings, initial)


def test_default_free_set_holds_the_unmeasured_idler():
    free = default_free(build_model("one-axis"))
    assert set(free) == {"k1", "k2", "k3", "J_1", "M", "B_1", "b", "tau_c1", "F_c"}


def test_shipped_pulses_recover_friction_inertia_and_belts_within_2_percent(fit):
    truth, result = fit
    print(f"one-axis fit: {result.wall_time_s:.2f} s, {result.iterations} iterations")
    assert result.success, result.message
    assert not result.not_identified
    for name, est in result.estimates.items():
        if est.free:
            assert est.estimate == pytest.approx(truth.values[name], rel=0.02), name
            assert est.identified, name


def test_fresh_plant_started_at_the_truth_stays_there():
    """A fresh simulated plant (study seed 6: the default free set x/÷1.3 off Table 2.3,
    standard one-axis pulses, rig sensors), started at the truth (x/÷1.0001).

    Before the state-estimation pre-pass (node states of the unmeasured idler estimated with
    the parameters held) only seeds 1 and 3 of 0-4 stayed at the truth. With it, 10 of 10
    seeds converge from the truth, worst errors 0.9-2.6 % (F_c, the cart's Coulomb friction
    seen only while the laser is valid, on 9 of 10). Seed 6 (worst 0.98 %, F_c) is asserted
    within 2 %, issue 5's target. Starts off by x3 still mostly fail (docs/fitting.md,
    "One-axis"), so they are not asserted. Measured ~5 s.
    """
    from hframe_id.fitting.study import run_trial

    trial = run_trial("one-axis", 6, start_factor=1.0001)
    print(trial.errors, trial.stages)
    assert trial.success, trial.message
    for name, error in trial.errors.items():
        assert abs(error) < 0.02, (name, error)
