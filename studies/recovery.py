"""Recovery and coverage studies on simulated data (used by tests/fitting/test_fit_recovery.py,
tests/fitting/test_fit_one_axis.py, ``studies.fleet`` and
``python -m studies.recovery``).

A study draws, per seed, a plant that is not a shipped file (the thesis's values times
log-uniform factors within x/÷ ``truth_spread``), simulates the standard experiments with the
rig's sensor models (encoder quantization, laser noise and range, DAC), starts the fit from
the truth times log-uniform factors within x/÷ ``start_factor`` for every free parameter (or,
with ``from_table``, from the thesis's table the plant was drawn around, as a user would),
and records the errors, whether each 95 % interval holds the truth, time and iterations.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from hframe_id.fitting.designs import standard_designs
from hframe_id.fitting.fit import fit_recordings
from hframe_id.fitting.options import FitOptions
from hframe_id.fitting.problem import default_free
from hframe_id.models import build_model, declaration
from hframe_id.parameters import ParameterSet, load_parameter_file
from hframe_id.recordings.simulated import simulate_recording


@dataclass
class Trial:
    """One seed of a study: the fit's outcome against the plant's truth.

    ``errors`` and ``covered`` are per free parameter (relative error, and whether the
    reported 95 % interval holds the truth; ``covered_gn``: the textbook Gauss-Newton one);
    coverage is judged only for parameters reported identified.
    """

    seed: int
    success: bool
    message: str
    errors: dict[str, float]  # relative error of each free parameter
    covered: dict[str, bool]  # 95 % interval holds the truth
    covered_gn: dict[str, bool]
    wall_time_s: float
    iterations: int
    evaluations: int
    identified: dict[str, bool] = field(default_factory=dict)
    stages: str = ""
    relative_std: dict[str, float] = field(default_factory=dict)
    relative_std_gn: dict[str, float] = field(default_factory=dict)

    @property
    def max_error(self) -> float:
        """Largest absolute relative error over the free parameters."""
        return max(abs(e) for e in self.errors.values())


def random_truth(variant: str, rng: np.random.Generator, spread: float) -> ParameterSet:
    """A plant that is not a shipped file: the variant's reference table with each default
    free parameter times a log-uniform factor within x/÷ ``spread``."""
    base = load_parameter_file(declaration(variant).reference_file, variant)
    model = build_model(variant)
    free = default_free(model)
    factors = {n: math.exp(rng.uniform(-math.log(spread), math.log(spread))) for n in free}
    truth = base.replace_values(**{n: base.values[n] * f for n, f in factors.items()})
    truth.title = f"random {variant} plant for recovery studies"
    return truth


def simulate_set(truth: ParameterSet, seed: int, designs=None) -> list:
    """Recordings of ``designs`` (default: the variant's standard experiments) simulated from
    ``truth`` at 1 kHz with the rig's sensor models, noise seeded ``seed * 100 + i``."""
    designs = designs or standard_designs(truth.variant, 1e-3)
    return [
        simulate_recording(truth, d.inputs, 1e-3, seed=seed * 100 + i, experiment={"name": d.name})
        for i, d in enumerate(designs)
    ]


def run_trial(
    variant: str,
    seed: int,
    start_factor: float = 3.0,
    truth_spread: float = 1.3,
    options: FitOptions | None = None,
    designs=None,
    from_table: bool = False,
) -> Trial:
    """Fit one seed's plant (:func:`random_truth`, x/÷ ``truth_spread``) from the truth times
    log-uniform factors within x/÷ ``start_factor`` (or from the reference table with
    ``from_table``) and compare with the truth."""
    rng = np.random.default_rng(seed)
    truth = random_truth(variant, rng, truth_spread)
    recordings = simulate_set(truth, seed, designs)
    options = options or FitOptions()
    model = build_model(variant)
    free = default_free(model) if options.free is None else None
    start_values = {}
    for name in free or []:
        start_values[name] = truth.values[name] * math.exp(
            rng.uniform(-math.log(start_factor), math.log(start_factor))
        )
    start = truth.replace_values(**start_values)
    if from_table:
        # What a user does: start from the thesis's table the plant was drawn around.
        start = load_parameter_file(declaration(variant).reference_file, variant)
    result = fit_recordings(recordings, start, options)
    errors, covered, covered_gn, identified = {}, {}, {}, {}
    z = 1.959963984540054
    for name, est in result.estimates.items():
        if not est.free:
            continue
        true = truth.values[name]
        errors[name] = est.estimate / true - 1
        identified[name] = est.identified
        if est.identified:
            covered[name] = est.ci95[0] <= true <= est.ci95[1]
            half = z * est.relative_std_gn
            covered_gn[name] = abs(math.log(est.estimate / true)) <= half
    return Trial(
        seed,
        result.success,
        result.message,
        errors,
        covered,
        covered_gn,
        result.wall_time_s,
        result.iterations,
        result.evaluations,
        identified,
        " | ".join(f"{st.iterations} it {st.wall_time_s:.1f}s" for st in result.stages),
        {n: e.relative_std for n, e in result.estimates.items() if e.free},
        {n: e.relative_std_gn for n, e in result.estimates.items() if e.free},
    )


def main(argv=None) -> int:
    """``python -m studies.recovery``: one line per seed, then the coverage."""
    parser = argparse.ArgumentParser(prog="python -m studies.recovery")
    parser.add_argument("--variant", default="hframe-8")
    parser.add_argument("--seeds", type=int, nargs="+", default=list(range(10)))
    parser.add_argument("--start-factor", type=float, default=3.0)
    parser.add_argument(
        "--from-table",
        action="store_true",
        help="start from the thesis's table (Table 4.2 / 2.3) instead of the truth x factors",
    )
    args = parser.parse_args(argv)
    trials = []
    for seed in args.seeds:
        t0 = time.perf_counter()
        trial = run_trial(args.variant, seed, args.start_factor, from_table=args.from_table)
        trials.append(trial)
        worst = max(trial.errors, key=lambda n: abs(trial.errors[n]))
        print(
            f"seed {seed:3d} success={trial.success} max err {100 * trial.max_error:.4f}% "
            f"({worst}) covered {sum(trial.covered.values())}/{len(trial.covered)} "
            f"(GN {sum(trial.covered_gn.values())}) time {trial.wall_time_s:.1f} s "
            f"it {trial.iterations} evals {trial.evaluations} [{time.perf_counter() - t0:.1f} s] "
            f"{trial.message} [{trial.stages}]",
            flush=True,
        )
    cov = [c for t in trials for c in t.covered.values()]
    cov_gn = [c for t in trials for c in t.covered_gn.values()]
    print(f"coverage {np.mean(cov):.3f} (GN {np.mean(cov_gn):.3f}) over {len(cov)} intervals")
    return 0


if __name__ == "__main__":
    sys.exit(main())
