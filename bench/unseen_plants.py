"""Unseen plants (issue 25): the fit's wall time on plants drawn from the issue's envelope, as a
ratio to the matched six-step fit timed in the same run, beside the study's two checks.

- Baseline: the fitter with ``FitOptions()`` from Table 4.2 on the six shipped steps
  (``datasets/{2,4,6}V_{x,y}motion.mcap``, recorded from an hframe-8 plant: the model matches),
  as in the fitting section's realistic-vs-matched comparison; the median wall time of
  ``--matched-repeats`` runs (default ``MATCHED_REPEATS``), timed first, in this process.
- Plants: the issue's named plants and dev seeds of ``studies.unseen_plants`` (default
  ``DEFAULT_NAMED`` and ``DEFAULT_SEEDS``; test seeds are refused), each recorded, fitted and
  judged by ``run_trial``: the six 1 s steps, an hframe-8 fit from Table 4.2 with
  ``FitOptions()``, training cost and held-out motor-angle rms against the plant's section-4.1
  reduction (pass: <= ``TRAINING_RATIO_MAX`` x and <= ``HELD_OUT_RATIO_MAX`` x).
- Per plant: the fit's wall time [s] (the ``fit_recordings`` call alone, as for the baseline),
  that time over the baseline's median, both checks' ratios and verdicts, the solver's success
  and how far the plant's true x or y travels [m]; then one summary line.

Wall times on a shared 2-core machine are noisy; the ratios measured in one run are the result.
With ``--jobs`` above 1 the plants are fitted side by side, each slowed by the others, while the
baseline ran alone: their ratios are then not comparable (default 1).

    python -m bench.unseen_plants                              # 4 + 3 plants, 9-13 minutes
    python -m bench.unseen_plants --named linear --seeds 3     # two plants, ~1 minute
    python -m bench.unseen_plants --named --seeds 8 11 --json /tmp/unseen.json
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from bench import heading
from bench.fitting import DATASETS, EXPERIMENTS, MATCHED_REPEATS
from hframe_id.atomic import replace_atomically
from hframe_id.fitting import FitOptions, fit_recordings
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings import read_recording
from studies.mismatch import TABLE_4_2
from studies.unseen_plants import (
    DEV_SEEDS,
    HELD_OUT_RATIO_MAX,
    NAMED,
    TRAINING_RATIO_MAX,
    Task,
    UnseenTrial,
    run_tasks,
    trial_document,
    whole_count,
)

#: The plants of the default run: the issue's four named plants and three dev seeds whose
#: plants stay within the rig's travel and move (docs/studies/2026-11-25-unseen-plants.md).
DEFAULT_NAMED = ("linear", "lubricated", "worn", "heavy")
DEFAULT_SEEDS = (3, 8, 11)

TABLE_HEADER = (
    "| plant | split | travel [m] | wall [s] | wall / matched | training cost / reduction's | "
    "held-out phi rms / reduction's | success | verdict |\n"
    "|---|---|---|---|---|---|---|---|---|"
)


@dataclass(frozen=True)
class Matched:
    """The matched six-step fit's timed runs: wall times [s] and the solver's success flags."""

    times_s: tuple[float, ...]
    successes: tuple[bool, ...]

    @property
    def median_s(self) -> float:
        """Median wall time [s]: the baseline of every plant's ratio."""
        return statistics.median(self.times_s)

    def line(self) -> str:
        """The baseline on one line."""
        times = ", ".join(f"{t:.1f}" for t in self.times_s)
        return (
            f"matched: six shipped steps, times {times} s, median {self.median_s:.1f} s, "
            f"success {sum(self.successes)}/{len(self.successes)}"
        )


def time_matched(repeats: int) -> Matched:
    """Fit the six shipped steps from Table 4.2 with ``FitOptions()`` ``repeats`` times, timing
    the ``fit_recordings`` call alone as ``run_trial`` does."""
    recordings = [read_recording(DATASETS / f"{stem}.mcap") for stem, _, _ in EXPERIMENTS]
    start = load_parameter_file(TABLE_4_2)
    times, successes = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fit_recordings(recordings, start, FitOptions())
        times.append(time.perf_counter() - t0)
        successes.append(bool(result.success))
    return Matched(tuple(times), tuple(successes))


def fitted(trial: UnseenTrial) -> bool:
    """Whether the trial's fit returned (its wall time is a fit's)."""
    return trial.success is not None


def wall_ratio(trial: UnseenTrial, matched_s: float) -> float:
    """The fit's wall time over the matched fit's ``matched_s`` [-]; NaN if it did not return."""
    return trial.wall_time_s / matched_s if fitted(trial) else math.nan


def _number(value: float, text: str) -> str:
    """``text`` (``value`` formatted), or ``-`` where ``value`` is NaN."""
    return "-" if math.isnan(value) else text


def _check(ratio: float, passed: bool) -> str:
    """``0.679 PASS``: a check's ratio and verdict; ``-`` if it was not reached."""
    return _number(ratio, f"{ratio:.3f} {'PASS' if passed else 'FAIL'}")


def verdict(trial: UnseenTrial) -> str:
    """``PASS`` (both checks), ``FAIL``, and any traceback or exit the trial ended with."""
    text = "PASS" if trial.passes_training and trial.passes_held_out else "FAIL"
    if trial.error is not None:
        e = trial.error
        kind = "EXIT" if e.stage == "process" else "TRACEBACK"
        text += f"; {kind} in {e.stage}: {e.type}: {e.message} at {e.where_own}"
    return text


def plant_row(trial: UnseenTrial, matched_s: float) -> str:
    """One plant as a row under ``TABLE_HEADER``."""
    ratio = wall_ratio(trial, matched_s)
    success = "-" if trial.success is None else "yes" if trial.success else "no"
    cells = (
        trial.draw.label,
        trial.split,
        _number(trial.travel_m, f"{trial.travel_m:.3g}"),
        _number(trial.wall_time_s, f"{trial.wall_time_s:.1f}"),
        _number(ratio, f"{ratio:.1f}x"),
        _check(trial.cost_ratio, trial.passes_training),
        _check(trial.held_out_ratio, trial.passes_held_out),
        success,
        verdict(trial),
    )
    return f"| {' | '.join(cells)} |"


def summary_line(trials: Sequence[UnseenTrial], matched_s: float) -> str:
    """Median and max wall-time ratio over the fits that returned, and the pass counts."""
    n = len(trials)
    ratios = [wall_ratio(t, matched_s) for t in trials if fitted(t)]
    timing = (
        f"wall / matched median {statistics.median(ratios):.1f}x, max {max(ratios):.1f}x "
        f"({len(ratios)} fits, matched {matched_s:.1f} s)"
        if ratios
        else "no fit returned"
    )
    training = sum(t.passes_training for t in trials)
    held_out = sum(t.passes_held_out for t in trials)
    both = sum(t.passes_training and t.passes_held_out for t in trials)
    success = sum(bool(t.success) for t in trials)
    errors = sum(t.error is not None for t in trials)
    return (
        f"unseen plants: {timing}; pass {both}/{n} (training {training}/{n}, held-out "
        f"{held_out}/{n}); success {success}/{n}; tracebacks or exits {errors}"
    )


def document(matched: Matched, trials: Sequence[UnseenTrial], jobs: int) -> dict:
    """The run as a JSON-ready dict: the baseline, the rows (``trial_document`` and the wall
    ratio, None where NaN) and the summary line."""
    ratios = [wall_ratio(t, matched.median_s) for t in trials]
    return {
        "section": "bench.unseen_plants",
        "jobs": jobs,
        "thresholds": {"training_ratio": TRAINING_RATIO_MAX, "held_out_ratio": HELD_OUT_RATIO_MAX},
        "matched": {
            "times_s": list(matched.times_s),
            "median_s": matched.median_s,
            "successes": list(matched.successes),
        },
        "summary": summary_line(trials, matched.median_s),
        "rows": [
            {**trial_document(t), "wall_ratio": r if math.isfinite(r) else None}
            for t, r in zip(trials, ratios, strict=True)
        ],
    }


def _dev_seed(text: str) -> int:
    """``--seeds`` for argparse: a seed of the dev split (the test split is the study's, once)."""
    seed = int(text)
    if seed not in DEV_SEEDS:
        raise argparse.ArgumentTypeError(
            f"{seed} is not a dev seed ({DEV_SEEDS.start}..{DEV_SEEDS.stop - 1})"
        )
    return seed


def make_parser() -> argparse.ArgumentParser:
    """The command line (``--help``)."""
    parser = argparse.ArgumentParser(
        prog="python -m bench.unseen_plants",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--named",
        nargs="*",
        choices=tuple(NAMED),
        default=list(DEFAULT_NAMED),
        help=f"the issue's named plants (default: {' '.join(DEFAULT_NAMED)}; none: --named)",
    )
    parser.add_argument(
        "--seeds",
        nargs="*",
        type=_dev_seed,
        default=list(DEFAULT_SEEDS),
        help=f"dev seeds of drawn plants (default: {' '.join(map(str, DEFAULT_SEEDS))}; none: "
        "--seeds)",
    )
    parser.add_argument(
        "--jobs",
        type=whole_count,
        default=1,
        help="plants fitted in parallel processes (default 1: only then are the wall ratios "
        "comparable)",
    )
    parser.add_argument(
        "--matched-repeats",
        type=whole_count,
        default=MATCHED_REPEATS,
        metavar="N",
        help=f"timed runs of the matched fit, median used (default {MATCHED_REPEATS})",
    )
    parser.add_argument("--json", type=Path, metavar="PATH", help="write the run to PATH")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Time the matched baseline, then fit and judge the plants, one row each as they finish."""
    args = make_parser().parse_args(argv)
    tasks: list[Task] = [("named", n) for n in args.named] + [("seed", s) for s in args.seeds]
    heading("Unseen plants: fit wall time / matched six-step fit (issue 25)")
    print(
        f"{len(tasks)} plant(s), {args.jobs} job(s); each: six 1 s steps, hframe-8 fit from "
        f"Table 4.2 with FitOptions(); pass: training cost <= {TRAINING_RATIO_MAX} x and "
        f"held-out phi rms <= {HELD_OUT_RATIO_MAX} x the reduction's",
        flush=True,
    )
    matched = time_matched(args.matched_repeats)
    print(matched.line(), end="\n\n", flush=True)
    print(TABLE_HEADER, flush=True)
    trials: list[UnseenTrial] = []
    for trial in run_tasks(tasks, args.jobs):
        trials.append(trial)
        print(plant_row(trial, matched.median_s), flush=True)
        if args.json:
            text = json.dumps(document(matched, trials, args.jobs), indent=1, allow_nan=False)
            replace_atomically(args.json, text + "\n")
    print(f"\n{summary_line(trials, matched.median_s)}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
