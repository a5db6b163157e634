"""One-axis drive (thesis ch. 2): the shipped 5 V + 10 V pulses recover the sim rig's truth.

datasets/{5,10}V_oneaxis.mcap were recorded (seed 2301, encoder quantization, 5 um laser
noise, laser range +/-5 cm: the cart is seen in 30-50 % of each pulse) from
datasets/truth/one-axis-rig.yaml: Table 2.1 + 2.3 with every belt stiffness x 0.9,
b = 19.9945 (start 19.0424, 5 % off) and F_c = 0.25 (start 0.2, 20 % off). The fit starts
from models/one-axis-table2.3.yaml.

The idler pulley (phi3) is not measured: by default its J_2, B_2, tau_c2 are held at the
start's values (here equal to the truth, so this test does not measure the bias a wrong
idler value causes; docs/studies/2026-11-22-one-axis.md does). Tolerance 2 % (issue 5's target
for friction and inertia; also applied to the stiffnesses); measured worst error 0.37 % (B_1),
stiffnesses within 0.05 %. Time printed, not asserted (measured 18 s, most of it the restarts
along k2, k3).
"""

import math
from pathlib import Path

import pytest

from hframe_id.fitting import fit_recordings
from hframe_id.fitting.problem import default_free
from hframe_id.models import build_model
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings import read_recording

#: The one-axis studies (shipped pulses, five fresh plants), about 4 min: run by
#: `make test-all` (and CI), not `make test`.
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[3]
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


#: Study seeds of the fresh-plant test: 0-4 of the ten measured in
#: docs/studies/2026-11-22-one-axis.md (seed 4 needs the restarts along k2, k3: without them it
#: stops at a secondary optimum, k2 +19 %).
FRESH_SEEDS = (0, 1, 2, 3, 4)


@pytest.mark.parametrize("seed", FRESH_SEEDS)
def test_fresh_plants_from_starts_off_by_10_percent(seed):
    """Fresh simulated plants (the default free set x/÷1.3 off Table 2.3, standard one-axis
    pulses, rig sensors), started x/÷1.1 off the truth (study ``--start-factor 1.1``).

    Measured over seeds 0-9 (docs/studies/2026-11-22-one-axis.md): 10 of 10 converge; stiffnesses
    within 0.67 %, J_1, M, B_1, b, tau_c1 within 1.72 % (issue 5's 2 % for friction and
    inertia); the cart's Coulomb friction F_c, seen only while the laser is valid, within
    2.55 %, more than 2 % on 5 of 10 seeds: its robust standard error is 1.3-4.9 %, so the
    pulses do not determine it to 2 %, and it is checked against its own interval instead
    (|error| / std error measured <= 1.7; asserted < 3). From Table 2.3: 9 of 10; from x/÷3:
    6 of 10, the other 4 reported as failed (docs/fitting.md, "One-axis").
    """
    from studies.recovery import run_trial

    trial = run_trial("one-axis", seed, start_factor=1.1)
    print(trial.errors, trial.stages)
    assert trial.success, trial.message
    for name, error in trial.errors.items():
        if name.startswith("k"):
            assert abs(error) < 0.01, (name, error)
        elif name == "F_c":
            assert abs(math.log1p(error)) < 3 * trial.relative_std[name], (name, error)
        else:
            assert abs(error) < 0.02, (name, error)
