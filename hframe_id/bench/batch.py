"""Batch fits on Dask (issue 11): the same 16 fits as an in-process sequential loop, on a
LocalCluster of 1 worker process and of 2, in the same run.

- Fits: a synthetic fleet (``hframe_id.fleet.synthetic``, 8 rigs x 2 weeks, seed 11): each
  fit is hframe-8 from Table 4.2 on three 1 s steps (3000 samples), one thread, the batch's
  options, parameter file written, no report (``--no-reports``).
- Sequential: ``run_job`` on each fit in this process, after ``warm_up`` (models derived,
  kernels loaded), as a loop without Dask would run them.
- Dask: ``run_batch`` with a fresh store on a running LocalCluster of single-threaded worker
  processes (started before the timing; its start is reported on its own): submit, fit,
  gather, store written. Workers are warmed by the batch's plugin inside the timing.
- Targets: 2 workers >= 1.7x one worker; Dask 1 worker within 10 % of the sequential loop.

On a shared 2-core machine the second worker competes with whatever else runs; the ratios
of one run are the result.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import time
from pathlib import Path

from distributed import Client, LocalCluster

from hframe_id.bench import heading
from hframe_id.fleet.job import batch_options, job_key, run_job, sha256_file, warm_up
from hframe_id.fleet.manifest import load_manifest
from hframe_id.fleet.runner import run_batch
from hframe_id.fleet.store import ResultsStore
from hframe_id.fleet.synthetic import make_fleet

RIGS, WEEKS, SEED = 8, 2, 11


def _sequential(jobs, out: Path) -> float:
    warm_up(jobs)
    start = time.perf_counter()
    for job in jobs:
        digests = [sha256_file(p) for p in job.recordings]
        row = run_job(job, job_key(job, batch_options(job), digests), digests, out, False)
        if row["status"] != "ok":
            print(f"  sequential: {job.rig} {row['status']}: {row['message']}")
    return time.perf_counter() - start


def _dask(jobs, workers: int, out: Path) -> tuple[float, float]:
    """(cluster start [s], batch wall time [s]) on a LocalCluster of ``workers``."""
    start = time.perf_counter()
    with (
        LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0"
        ) as cluster,
        Client(cluster) as client,
    ):
        client.wait_for_workers(workers)
        started = time.perf_counter() - start
        store = ResultsStore(out / "results.parquet")
        summary = run_batch(
            jobs, store, lambda: contextlib.nullcontext(client), out / "fits", reports=False
        )
    if summary.stored.get("ok") != len(jobs):
        print(f"  dask {workers}: {summary.line()}")
    return started, summary.wall_time_s


def run() -> None:
    heading(f"Batch fits on Dask ({RIGS * WEEKS} fits: {RIGS} rigs x {WEEKS} weeks)")
    load = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="hframe-bench-batch-") as tmp:
        root = Path(tmp)
        start = time.perf_counter()
        jobs = load_manifest(make_fleet(RIGS, WEEKS, SEED, root / "fleet"))
        print(f"fleet recorded in {time.perf_counter() - start:.1f} s", flush=True)
        sequential = _sequential(jobs, root / "sequential")
        print(f"sequential loop (in process): {sequential:6.1f} s", flush=True)
        times = {}
        for workers in (1, 2):
            started, times[workers] = _dask(jobs, workers, root / f"dask-{workers}")
            print(
                f"Dask, {workers} worker(s):           {times[workers]:6.1f} s "
                f"(cluster start {started:.1f} s, not included)",
                flush=True,
            )
    n = len(jobs)
    print(f"\nper fit: sequential {sequential / n:.2f} s, Dask 1 {times[1] / n:.2f} s, "
          f"Dask 2 {times[2] / n:.2f} s (wall time / fits)")  # fmt: skip
    overhead = times[1] / sequential - 1
    speedup = times[1] / times[2]
    print(f"Dask 1 worker vs sequential: {100 * overhead:+.1f} % (target <= +10 %)")
    print(f"2 workers vs 1 worker: {speedup:.2f}x (target >= 1.7x)")
    print(
        f"load average (1 min) at start {load[0]:.1f}, at end {os.getloadavg()[0]:.1f} on "
        f"{os.cpu_count()} CPUs: other processes take cores from the second worker"
    )
