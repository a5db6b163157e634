"""Recovery on simulated data: the issue's accuracy, robustness and coverage targets.

The study (``studies.recovery``) draws a plant that is not a shipped file (Table 4.2
values times log-uniform factors within x/÷1.3, per seed), simulates the six step experiments
of section 4.4 with the rig's sensor models (321084-count encoders, 5 um lasers with their
5 cm range, 12-bit DAC), and starts every free parameter off by a log-uniform factor within
x/÷3. Seeds are fixed; no timing assertions (shared 2-core machines).

Tolerances:
- recovery 1 %: the issue's target. Measured worst error over seeds 0-9: 0.09 %
  (F_c_cart); the solver's step tolerance (1e-6 relative) is 1000x below it.
- coverage: nominal 95 % intervals; measured 0.988 over 160 intervals (10 seeds x 16
  parameters). The assertion [0.85, 1.0] fails for the textbook Gauss-Newton intervals
  (measured 0.30) and the HAC sandwich alone (0.73), so it tests that the noise model is in.
"""

import numpy as np
import pytest

from studies.recovery import run_trial

#: the 10-seed recovery study, about 1 min: run by `make test-all` (and CI), not `make test`.
pytestmark = pytest.mark.slow

SEEDS = range(10)
RECOVERY_TOL = 0.01


@pytest.fixture(scope="module")
def trials():
    return [run_trial("hframe-8", seed, start_factor=3.0) for seed in SEEDS]


def test_every_parameter_within_1_percent_for_at_least_9_of_10_seeds(trials):
    good = [t for t in trials if t.success and t.max_error <= RECOVERY_TOL]
    report = {t.seed: (t.success, round(100 * t.max_error, 4)) for t in trials}
    assert len(good) >= 9, report


def test_every_free_parameter_is_identified_from_the_six_experiments(trials):
    for trial in trials:
        assert all(trial.identified.values()), (trial.seed, trial.identified)


def test_95_percent_intervals_cover_the_truth_about_95_percent_of_the_time(trials):
    covered = [c for t in trials for c in t.covered.values()]
    covered_gn = [c for t in trials for c in t.covered_gn.values()]
    coverage = float(np.mean(covered))
    print(f"coverage {coverage:.3f} (textbook Gauss-Newton {np.mean(covered_gn):.3f})")
    assert len(covered) == 16 * len(SEEDS)
    assert 0.85 <= coverage <= 1.0
    # The textbook intervals are far too narrow here (quantization is not white noise):
    # the noise-model intervals must be the reason for the coverage above.
    assert np.mean(covered_gn) < 0.7
