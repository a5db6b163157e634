"""One fit of a batch, as run on a Dask worker: read, fit, write the fit's files, return a row.

``run_job`` never raises for a bad fit: a solver that fails and an error while reading or
fitting both come back as a row with ``status`` ``failed`` or ``error`` and the message, so
that one bad run never stops a batch. A fit's files are written into a hidden folder of
its own (``staged_folder``) and put in place by the client when it stores the fit's row
(``runner.place_files``): a row and its files are stored together, and a fit whose row is
never stored (Ctrl-C, a worker that died and whose task ran again) leaves no files.

The compiled kernels live in per-process caches
(``functools.lru_cache`` in ``hframe_id.fitting.kernel``) over an on-disk cache of shared
libraries; a worker process keeps them between tasks, so each is built (or loaded) once per
worker, and ``warm_up`` builds them before the first task.
"""

from __future__ import annotations

import os
import shutil
import socket
import time
import warnings
from pathlib import Path
from typing import Any

from hframe_id.fitting import FitResult, fit_recordings
from hframe_id.fitting.kernel import compiled_windows
from hframe_id.fitting.output import write_parameter_file
from hframe_id.fitting.problem import resolve_free
from hframe_id.fitting.report import write_report
from hframe_id.fleet.keys import base_row, batch_options, batch_options_for, staged_folder
from hframe_id.fleet.manifest import FitJob
from hframe_id.models import build_model
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings import read_recording


def fit_kinds(jobs: list[FitJob]) -> list[tuple[str, tuple[str, ...]]]:
    """The distinct (model, free set) pairs of ``jobs`` (``()``: the model's default set),
    each of which has its own compiled kernels."""
    return sorted({(job.model, job.free or ()) for job in jobs})


def warm_up(kinds: list[tuple[str, tuple[str, ...]]]) -> None:
    """Derive the models and build (or load from the disk cache, ``HFRAME_ID_CACHE``) the
    compiled window kernels of each (model, free set) of ``fit_kinds`` in this process, so
    that no task pays for them."""
    for model_name, free in kinds:
        model = build_model(model_name)
        options = batch_options_for(model_name, free or None)
        names = resolve_free(model, options)
        compiled_windows(model, tuple(model.parameter_names.index(n) for n in names))
        compiled_windows(model, None)


def run_job(
    job: FitJob, key: str, digests: list[str], out_dir: Path, reports: bool
) -> dict[str, Any]:
    """Fit ``job`` and write its parameter file (and, with ``reports``, its report) into
    ``staged_folder(out_dir, key)``; the store's row for it (``status``, ``message``,
    estimates, timings; the files named where they will be once placed in ``out_dir``)."""
    row = base_row(job, key, digests)
    staged = staged_folder(out_dir, key)
    row["worker"] = f"{socket.gethostname()}:{os.getpid()}"
    start = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            recordings = [read_recording(p) for p in job.recordings]
            initial = load_parameter_file(job.initial, variant=job.model)
            result = fit_recordings(recordings, initial, batch_options(job))
            shutil.rmtree(staged, ignore_errors=True)  # an earlier attempt's (a dead worker)
            staged.mkdir(parents=True)
            fit_id, written = write_parameter_file(
                result, recordings, list(job.recordings), job.initial, staged
            )
            parameter_file = out_dir / written.name if written else None
            report = (
                out_dir / write_report(result, recordings, fit_id, parameter_file, staged).name
                if reports
                else None
            )
    except Exception as err:  # any failure of one fit is its row, not the batch's end
        shutil.rmtree(staged, ignore_errors=True)
        row.update(status="error", message=f"{type(err).__name__}: {err}")
        row["wall_time [s]"] = time.perf_counter() - start
        return row
    row.update(
        status="ok" if result.success else "failed",
        message=result.message,
        fit_id=fit_id,
        parameter_file=str(parameter_file) if parameter_file else None,
        report=str(report) if report else None,
    )
    row.update(result_columns(result))
    row["wall_time [s]"] = time.perf_counter() - start
    return row


def result_columns(result: FitResult) -> dict[str, Any]:
    """The model the fit kept (``fitted_model``: the job's, or the larger one it nests in where
    the data chose that, ``fitting.structure_choice``), estimate, std error, 95 % interval and
    identified flag of every free parameter, the residual rms per channel and in noise std,
    cost, iterations and the solver's time."""
    columns: dict[str, Any] = {
        "fitted_model": result.variant,
        "cost": float(result.cost),
        "iterations": int(result.iterations),
        "fit_time [s]": float(result.wall_time_s),
        "residual_rms [noise std]": result.residual_rms,
    }
    for name, est in result.estimates.items():
        if not est.free:
            continue
        unit = f"[{est.unit}]"
        columns[f"{name} {unit}"] = float(est.estimate)
        columns[f"{name} std {unit}"] = float(est.std_error)
        columns[f"{name} ci95 low {unit}"] = float(est.ci95[0])
        columns[f"{name} ci95 high {unit}"] = float(est.ci95[1])
        columns[f"{name} identified"] = bool(est.identified)
    units = {s.name: s.unit for s in build_model(result.variant).outputs}
    for channel, rms in result.diagnostics.channel_rms.items():
        columns[f"rms {channel} [{units.get(channel, 'SI')}]"] = float(rms)
    return columns
