"""Run a manifest's fits on a Dask cluster, storing each row as it arrives.

``client.submit(run_job, ...)`` per fit, then ``as_completed``: every finished fit's files
are put in place (``place_files``) and its row added to the store, which is written
(atomically) at most every ``flush_interval_s`` and at the end, so a crash or Ctrl-C loses
only unfinished fits, and leaves none of their files (their staged folders are removed once
the cluster is closed). A worker that dies mid-fit has its task
rescheduled on another worker by the scheduler (``distributed.scheduler.allowed-failures``
times, default 3); a task that outlives that many workers becomes an ``error`` row.
"""

from __future__ import annotations

import logging
import os
import shutil
import signal
import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import dask
from distributed import Client, LocalCluster, as_completed
from distributed.diagnostics.plugin import WorkerPlugin

from hframe_id.digests import sha256_file
from hframe_id.errors import HframeIdError, shown
from hframe_id.fleet.keys import base_row, batch_options, job_key, staged_folder
from hframe_id.fleet.manifest import FitJob
from hframe_id.fleet.store import ResultsStore


@dataclass
class BatchSummary:
    """What a batch did: fits planned, skipped (already stored), stored by status, wall time
    [s]."""

    planned: int
    skipped: int
    stored: dict[str, int] = field(default_factory=dict)
    wall_time_s: float = 0.0

    def line(self) -> str:
        """One line for the user: planned, skipped, stored by status, wall time [s]."""
        counts = ", ".join(f"{n} {status}" for status, n in sorted(self.stored.items()))
        done = sum(self.stored.values())
        return (
            f"{self.planned} fit(s): {self.skipped} already stored, {done} stored now"
            + (f" ({counts})" if counts else "")
            + f" in {self.wall_time_s:.1f} s"
        )


class KernelWarmUp(WorkerPlugin):
    """Builds the batch's models and compiled kernels once on every worker, including
    workers that join (or replace a dead one) later."""

    def __init__(self, kinds: list[tuple[str, tuple[str, ...]]]) -> None:
        self.kinds = kinds

    def setup(self, worker) -> None:
        """Build the batch's compiled kernels once on ``worker`` as it starts."""
        from hframe_id.fleet.job import warm_up

        warm_up(self.kinds)


#: Worker-process environment Dask sets that the fits do not want: a static glibc trim
#: threshold (64 KiB) also switches off glibc's adaptive mmap threshold, so every array of
#: more than 128 KiB is mapped and unmapped afresh; measured: a fit 1.29 -> 1.72 s a task.
SLOW_WORKER_ENVIRONMENT = ("MALLOC_TRIM_THRESHOLD_",)


@contextmanager
def local_cluster(workers: int) -> Iterator[LocalCluster]:
    """A LocalCluster of ``workers`` single-threaded worker processes on this machine, their
    environment Dask's without ``SLOW_WORKER_ENVIRONMENT`` (one BLAS thread each kept).

    The key is removed from ``distributed.nanny.pre-spawn-environ`` after ``distributed`` is
    imported (dask/distributed#8143: importing it restores removed defaults). Dask's own log
    lines are silenced up to its errors (a cancelled fit's warnings are no news to the user,
    and a worker whose heartbeat meets the scheduler closing at the end of a batch logged a
    CommClosedError traceback at error level: what goes wrong in a fit is its row's), and on
    Ctrl-C or SIGTERM (``KeyboardInterrupt``) the worker processes are killed at once:
    a worker in the middle of a fit would otherwise be waited for (4 s) before the nanny
    kills it, and its files would be written meanwhile."""
    environ = dask.config.get("distributed.nanny.pre-spawn-environ", default={})
    kept = {k: v for k, v in environ.items() if k not in SLOW_WORKER_ENVIRONMENT}
    with (
        dask.config.set({"distributed.nanny.pre-spawn-environ": kept}),
        LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",
            silence_logs=logging.CRITICAL,
        ) as cluster,
    ):
        try:
            yield cluster
        except KeyboardInterrupt:
            # Dask's complaints about the workers killed here are no news to the user.
            dask_logger = logging.getLogger("distributed")
            level = dask_logger.level
            dask_logger.setLevel(logging.CRITICAL)
            try:
                for nanny in list(cluster.workers.values()):
                    if getattr(nanny, "pid", None):
                        os.kill(nanny.pid, signal.SIGKILL)
                cluster.close()
            finally:
                dask_logger.setLevel(level)
            raise


class ClusterError(HframeIdError):
    """The Dask scheduler cannot be reached."""


#: Seconds to wait for a scheduler given by its address before giving up.
CONNECT_TIMEOUT_S = 10


@contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None) -> Iterator[Client]:
    """A client of the cluster at ``scheduler``, used as it is (``ClusterError`` if it does
    not answer within ``CONNECT_TIMEOUT_S``), or of a ``local_cluster`` of ``workers`` worker
    processes (default: the CPU count) on this machine."""
    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except Exception as err:  # OSError, a malformed address, a peer that is no scheduler
            reason = str(err).splitlines()[0] if str(err) else type(err).__name__
            raise ClusterError(
                f"--scheduler {shown(scheduler)}: cannot connect: {shown(reason)}"
            ) from None
        with client:
            yield client
        return
    with local_cluster(workers or os.cpu_count() or 1) as cluster, Client(cluster) as client:
        yield client


def pending_jobs(
    jobs: list[FitJob], store: ResultsStore, force: bool
) -> tuple[list[tuple[FitJob, str, list[str]]], int]:
    """The fits to run as (job, key, recordings' sha256), and how many are skipped because
    the store holds their key (none with ``force``)."""
    pending, skipped = [], 0
    for job in jobs:
        digests = [sha256_file(p) for p in job.recordings]
        key = job_key(job, batch_options(job), digests)
        if key in store and not force:
            skipped += 1
        else:
            pending.append((job, key, digests))
    return pending, skipped


def run_batch(
    jobs: list[FitJob],
    store: ResultsStore,
    connect: Callable[[], AbstractContextManager[Client]],
    out_dir: Path,
    *,
    force: bool = False,
    reports: bool = True,
    flush_interval_s: float = 2.0,
    progress: Callable[[dict[str, Any], int, int], None] | None = None,
) -> BatchSummary:
    """Fit every job the store lacks (all with ``force``) on the cluster ``connect`` gives.

    Parameters
    ----------
    jobs : the manifest's fits.
    store : the results store; rows are added as fits finish.
    connect : returns a context manager giving the Dask client (``dask_client``, or
        ``lambda: contextlib.nullcontext(client)``); called only if a fit is pending, so a
        re-run with everything stored starts no cluster.
    out_dir : where the fits' parameter files and reports go.
    force : redo fits already stored.
    reports : write each fit's report with plots (about 3 s per fit) beside its YAML.
    flush_interval_s : the store is written at most this often [s] while fits arrive.
    progress : called with (row, rows done, rows pending) after each stored row.

    A KeyboardInterrupt cancels the unfinished fits, writes the finished rows and propagates.
    """
    start = time.perf_counter()
    pending, skipped = pending_jobs(jobs, store, force)
    summary = BatchSummary(len(jobs), skipped)
    if not pending:
        summary.wall_time_s = time.perf_counter() - start
        return summary
    made = not out_dir.exists()
    try:
        with connect() as client:
            _run(client, pending, store, summary, out_dir, reports, flush_interval_s, progress)
    finally:  # the unfinished fits' files (their workers are stopped by now, local ones)
        for _, key, _ in pending:
            shutil.rmtree(staged_folder(out_dir, key), ignore_errors=True)
        if made:
            _remove_if_empty(out_dir)
    summary.wall_time_s = time.perf_counter() - start
    return summary


def _remove_if_empty(folder: Path) -> None:
    """Remove ``folder`` if nothing is in it: the batch made it, and no fit stored files
    there (Ctrl-C before the first row left an empty ``<results>-fits/``)."""
    try:
        folder.rmdir()
    except OSError:  # not empty, or gone
        pass


def place_files(row: dict[str, Any], out_dir: Path) -> dict[str, Any]:
    """Move the files of ``row``'s fit from its staged folder into ``out_dir``, all or none:
    the row as it is, or an ``error`` row if a file of that name is there already."""
    staged = staged_folder(out_dir, row["key"])
    entries = sorted(staged.iterdir()) if staged.is_dir() else []
    taken = [entry.name for entry in entries if (out_dir / entry.name).exists()]
    if taken:
        shutil.rmtree(staged, ignore_errors=True)
        return {
            **row,
            "status": "error",
            "message": f"{out_dir / taken[0]} exists already; the fit's files are not stored",
            "parameter_file": None,
            "report": None,
        }
    for entry in entries:
        os.replace(entry, out_dir / entry.name)
    if staged.is_dir():
        staged.rmdir()
    return row


def _run(client, pending, store, summary, out_dir, reports, flush_interval_s, progress) -> None:
    from hframe_id.fleet.job import fit_kinds, run_job  # solver and plots: only if pending

    kinds = fit_kinds([job for job, _, _ in pending])
    client.register_plugin(KernelWarmUp(kinds), name="hframe-id-warm")
    futures = {
        client.submit(
            run_job, job, key, digests, out_dir, reports, key=f"fit-{key[:20]}", pure=False
        ): (job, key, digests)
        for job, key, digests in pending
    }
    last_flush = time.perf_counter()
    try:
        for future in as_completed(futures):
            row = place_files(_row(future, *futures[future]), out_dir)
            store.add(row)
            summary.stored[row["status"]] = summary.stored.get(row["status"], 0) + 1
            if time.perf_counter() - last_flush >= flush_interval_s:
                store.flush()
                last_flush = time.perf_counter()
            if progress is not None:
                progress(row, sum(summary.stored.values()), len(pending))
    except KeyboardInterrupt:
        client.cancel(list(futures))
        raise
    finally:
        store.flush()


def _row(future, job: FitJob, key: str, digests: list[str]) -> dict[str, Any]:
    """The future's row, or an ``error`` row if the task itself failed (its workers died)."""
    try:
        row = future.result()
    except Exception as err:
        row = base_row(job, key, digests)
        row.update(status="error", message=f"{type(err).__name__}: {err}")
    return row
