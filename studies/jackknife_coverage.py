"""Jackknife coverage study: over noise seeds of the shipped realistic plant, how often the
experiment-level jackknife's 95 % intervals (``fitting.jackknife``) hold the across-seed mean
estimate and the plant's section-4.1 reduction, next to the fit's own intervals.

Per noise seed: the six section-4.4 steps recorded from the shipped plant
(``studies.mismatch.training_recordings``), the hframe-8 fit from Table 4.2 with the default
options, the leave-one-recording-out cross-validation (six more fits) and its jackknife
intervals, as ``hframe-id fit`` gives them.

    python -m studies.jackknife_coverage --noise-seeds 0 1 2 3 4
"""

from __future__ import annotations

import argparse
import sys
from types import SimpleNamespace

import numpy as np

from hframe_id.fitting import FitOptions, fit_recordings
from hframe_id.fitting.jackknife import with_jackknife_intervals
from hframe_id.parameters import load_parameter_file
from hframe_id.validation.cross_validation import leave_one_out
from studies.mismatch import TABLE_4_2, coverage_of_mean, plant_for, training_recordings


def run_seed(noise_seed: int) -> tuple[dict, dict, bool]:
    """({name: (estimate, low, high)} of the fit's own intervals, the same of the jackknife's,
    whether the fit and every fold converged) for one noise seed of the shipped plant."""
    recordings = training_recordings(plant_for(-1), noise_seed)
    initial = load_parameter_file(TABLE_4_2)
    options = FitOptions()
    result = fit_recordings(recordings, initial, options)
    table = leave_one_out(recordings, initial, options)
    result = with_jackknife_intervals(result, table)
    own, jackknife = {}, {}
    for name, est in result.estimates.items():
        if est.jackknife_ci95 is not None:
            own[name] = (est.estimate, *est.ci95)
            jackknife[name] = (est.estimate, *est.jackknife_ci95)
    converged = result.success and all(fold.success for fold in table.folds)
    return own, jackknife, converged


def holds(intervals: list[dict], values: dict[str, float]) -> float:
    """Share of the intervals (over seeds and parameters) that hold ``values[name]``."""
    hits = [low <= values[n] <= high for per in intervals for n, (_, low, high) in per.items()]
    return float(np.mean(hits)) if hits else float("nan")


def main(argv: list[str] | None = None) -> int:
    """The command line of this study (``--help``); prints one line per seed, then the
    coverages."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--noise-seeds", type=int, nargs="+", default=list(range(5)))
    args = parser.parse_args(argv)
    reduction = plant_for(-1).reference().values
    own_all, jackknife_all = [], []
    for seed in args.noise_seeds:
        own, jackknife, converged = run_seed(seed)
        print(
            f"noise seed {seed}: converged (fit and folds) {converged}, jackknife intervals for "
            f"{len(jackknife)} parameters; outside the reduction: "
            f"{[n for n, (_, lo, hi) in jackknife.items() if not lo <= reduction[n] <= hi]}",
            flush=True,
        )
        if jackknife:
            own_all.append(own)
            jackknife_all.append(jackknife)
    # Parameters at a bound in some seed have no jackknife interval there: the across-seed
    # mean is taken over the parameters every seed gives one.
    common = set.intersection(*(set(per) for per in jackknife_all)) if jackknife_all else set()
    for label, intervals in (("fit's own", own_all), ("jackknife", jackknife_all)):
        trials = [
            SimpleNamespace(estimates={n: v for n, v in per.items() if n in common})
            for per in intervals
        ]
        mean = coverage_of_mean(trials) if len(trials) > 1 else float("nan")
        print(
            f"{label} intervals over {len(intervals)} seeds: hold the across-seed mean "
            f"{mean:.3f}, the plant's reduction {holds(intervals, reduction):.3f}",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
