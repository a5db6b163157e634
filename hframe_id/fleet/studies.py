"""Recovery and coverage studies (``hframe_id.fitting.study``) with their trials on Dask.

Each trial (draw a plant, simulate the standard experiments, fit from a perturbed start) is
one task, one thread, on the same clusters as ``hframe-id batch`` (``runner.dask_client``:
a LocalCluster or ``--scheduler``); trials arrive as they finish. ``python -m
hframe_id.fleet.studies --seeds 0 1 2 3 --workers 2`` prints what the sequential
``python -m hframe_id.fitting.study`` prints per seed, and the coverage.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager

import numpy as np
from distributed import Client, as_completed

from hframe_id.fitting.options import FitOptions
from hframe_id.fitting.study import Trial, run_trial
from hframe_id.fleet.runner import dask_client


def run_trials(
    connect: Callable[[], AbstractContextManager[Client]],
    variant: str,
    seeds: Sequence[int],
    *,
    start_factor: float = 3.0,
    from_table: bool = False,
    on_trial: Callable[[Trial], None] | None = None,
) -> list[Trial]:
    """``run_trial(variant, seed, ...)`` for every seed on the cluster ``connect`` gives,
    single-threaded fits; the trials in seed order. ``on_trial`` sees each as it arrives."""
    options = FitOptions(threads=1, verbose=0)
    trials = []
    with connect() as client:
        futures = [
            client.submit(
                run_trial,
                variant,
                seed,
                start_factor,
                options=options,
                from_table=from_table,
                key=f"trial-{variant}-{seed}-{start_factor}-{from_table}",
            )
            for seed in seeds
        ]
        for future in as_completed(futures):
            trial = future.result()
            trials.append(trial)
            if on_trial is not None:
                on_trial(trial)
    return sorted(trials, key=lambda t: t.seed)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hframe_id.fleet.studies")
    parser.add_argument("--variant", default="hframe-8")
    parser.add_argument("--seeds", type=int, nargs="+", default=list(range(10)))
    parser.add_argument("--start-factor", type=float, default=3.0)
    parser.add_argument("--from-table", action="store_true")
    parser.add_argument("--scheduler", metavar="ADDRESS")
    parser.add_argument("--workers", type=int, metavar="N")
    args = parser.parse_args(argv)

    def show(trial: Trial) -> None:
        print(
            f"seed {trial.seed:3d} success={trial.success} max err "
            f"{100 * trial.max_error:.4f}% covered {sum(trial.covered.values())}/"
            f"{len(trial.covered)} time {trial.wall_time_s:.1f} s {trial.message}",
            flush=True,
        )

    trials = run_trials(
        lambda: dask_client(args.scheduler, args.workers),
        args.variant,
        args.seeds,
        start_factor=args.start_factor,
        from_table=args.from_table,
        on_trial=show,
    )
    covered = [c for t in trials for c in t.covered.values()]
    print(f"coverage {np.mean(covered):.3f} over {len(covered)} intervals")
    return 0


if __name__ == "__main__":
    sys.exit(main())
