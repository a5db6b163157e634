"""A fit's versioned parameter file: the fitted values plus provenance and uncertainty.

The file is an ordinary parameter file (``hframe_id.parameters``), so the simulator, the
controller and the exporters read it like the thesis's; its header adds

- ``provenance``: fit id, time, software version and git commit, every dataset with its
  sha256, model variant and options, free parameters with their initial values and the file
  they came from, solver status, iterations, final cost, wall time, and the channels' noise
  levels: how the fit weighed each channel and its residual rms, with the model-mismatch
  statement when the model does not follow the data at the sensors' noise level;
- ``uncertainty``: per free parameter the estimate, standard error, 95 % interval, whether the
  data identify it (and which experiments would), whether the box stopped it (``at_bound``)
  and whether the data bound it on one side only (``open_ended``),
  after a cross-validation the experiment-level jackknife's std and 95 % interval, plus the
  correlation matrix.

Only a successful fit gets a parameter file: a failed one must not be taken for a good one.
"""

from __future__ import annotations

import hashlib
import math
import subprocess
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from hframe_id import __version__
from hframe_id.digests import sha256_file
from hframe_id.errors import FitError
from hframe_id.fitting.report import mismatch_statement, output_units
from hframe_id.fitting.result import FitResult
from hframe_id.fitting.solvers import solver_named
from hframe_id.parameters import ParameterSet, save_parameter_file
from hframe_id.recordings.recording import Recording
from hframe_id.resources import portable_path, project_root


def git_commit() -> str:
    """The source tree's commit (with ``-dirty`` if it has changes), or ``"unknown"`` (also
    when installed from a wheel: a git repository around site-packages is not its source)."""
    root = project_root()
    if root is None:
        return "unknown"
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, timeout=5
        )
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=root,
            capture_output=True,
            text=True,
            timeout=5,
        )
    except (OSError, subprocess.TimeoutExpired):
        return "unknown"
    if commit.returncode != 0:
        return "unknown"
    return commit.stdout.strip() + ("-dirty" if dirty.stdout.strip() else "")


def make_fit_id(variant: str, dataset_hashes: list[str], when: datetime) -> str:
    """``<variant>-<UTC time>-<6 hex of the data>``: sortable, unique per data and second."""
    data = hashlib.sha256("".join(sorted(dataset_hashes)).encode()).hexdigest()[:6]
    return f"{variant}-{when.strftime('%Y%m%dT%H%M%SZ')}-{data}"


def unused_fit_id(out_dir: Path, fit_id: str) -> str:
    """``fit_id``, or ``fit_id-2``, ``-3``, ... if ``out_dir`` holds any file of that id
    already (two fits of the same data in the same second): nothing is ever overwritten,
    the parameter file, the report and its plots alike."""
    candidate, n = fit_id, 1
    while any(
        (out_dir / name).exists()
        for name in (f"{candidate}.yaml", f"{candidate}-report.md", f"{candidate}-plots")
    ):
        n += 1
        candidate = f"{fit_id}-{n}"
    return candidate


def _number(value: float) -> float:
    return float(f"{value:.10g}")


def provenance(
    result: FitResult,
    recordings: list[Recording],
    dataset_paths: list[Path],
    initial_path: Path | None,
    fit_id: str,
    when: datetime,
) -> dict[str, Any]:
    """The ``provenance`` block of a fitted parameter file: fit id, time (UTC), software and
    git commit, model and its options, each recording (file, sha256, samples, duration [s]),
    the initial file and the fit's options, stages and outcome: enough to redo the fit."""
    hashes = [sha256_file(path) for path in dataset_paths]
    return {
        "fit_id": fit_id,
        "created_utc": when.isoformat(timespec="seconds"),
        "software": f"hframe-id {__version__}",
        "git_commit": git_commit(),
        "model": result.variant,
        "model_options": {
            "smoothing_final": list(result.options.smoothing)
            if result.options.smoothing
            else "model default (1e-3 m/s, 1e-2 rad/s)",
        },
        "datasets": [
            {
                "file": portable_path(path),
                "sha256": digest,
                "samples": rec.n_samples,
                "duration_s": _number(rec.duration_s),
                "protocol": str(rec.experiment.get("notes", rec.experiment.get("protocol", ""))),
            }
            for path, digest, rec in zip(dataset_paths, hashes, recordings, strict=True)
        ],
        "fit_options": result.options.describe(),
        "free_parameters": list(result.free_names),
        "initial_values": {
            est.key: _number(est.initial) for est in result.estimates.values() if est.free
        },
        "initial_source": str(initial_path) if initial_path else result.initial.source,
        "solver": {
            "method": "multiple shooting, " + solver_named(result.options.solver).description,
            "success": bool(result.success),
            "message": result.message,
            "iterations": int(result.iterations),
            "final_cost": _number(result.cost),
            "residual_rms_noise_std": _number(result.residual_rms),
            "residual_rms_sensor_std": _number(result.residual_rms_sensor),
            "wall_time_s": round(float(result.wall_time_s), 3),
        },
        "not_identified_held_at_initial": list(result.not_identified),
        "noise": noise_levels(result),
    }


def noise_levels(result: FitResult) -> dict[str, Any]:
    """How the fit weighed each channel (the sensor's std, or a level estimated from the
    residuals under model mismatch) and its residual rms, SI with the unit in every key."""
    noise = result.diagnostics.noise
    units = output_units(result.variant)
    statement = mismatch_statement(result)
    channels = {}
    for name, channel in noise.channels.items():
        unit = units[name]
        channels[name] = {
            f"sensor_std [{unit}]": _number(channel.sensor_std),
            f"weight_std [{unit}]": _number(channel.weight_std),
            f"residual_rms [{unit}]": _number(channel.residual_rms),
            "residual_rms [sensor std]": _number(channel.residual_rms_sensor_std),
        }
        if channel.differs_by_recording:
            channels[name][f"weight_std_by_recording [{unit}]"] = {
                recording: _number(level)
                for recording, level in zip(
                    result.experiment_names, channel.recording_std, strict=True
                )
            }
    return {
        "weights": (
            "estimated from the residuals" if noise.method == "estimated" else "sensor noise"
        ),
        "rounds": int(noise.rounds),
        **(
            {
                "levels_settled": bool(noise.settling.settled),
                "levels_last_change": _number(math.expm1(noise.settling.change)),
            }
            if noise.settling is not None
            else {}
        ),
        "model_mismatch": statement is not None,
        **({"statement": statement} if statement else {}),
        "channels": channels,
    }


def uncertainty(result: FitResult) -> dict[str, Any]:
    """The ``uncertainty`` block of a fitted parameter file: per free parameter the estimate,
    standard error and interval (SI units), identifiability and bound flags, the jackknife's
    std and interval when cross-validated; the method, confidence level, held parameters and
    the correlation matrix."""
    level = f"{round(100 * result.options.confidence)} %"
    per_parameter = {}
    for est in result.estimates.values():
        if not est.free:
            continue
        per_parameter[est.key] = {
            "estimate": _number(est.estimate),
            "std_error": _number(est.std_error),
            f"interval_{level.replace(' %', '')}": [_number(est.ci95[0]), _number(est.ci95[1])],
            "identified": bool(est.identified),
            "at_bound": bool(est.at_bound),
            "open_ended": est.open_ended or None,
            **(
                {
                    "jackknife_std": _number(est.jackknife_std),
                    f"interval_{level.replace(' %', '')}_jackknife": [
                        _number(v) for v in est.jackknife_ci95
                    ],
                }
                if est.jackknife_ci95
                else {}
            ),
            **({"identified_by": list(est.identified_by)} if est.identified_by else {}),
        }
    held = result.held_statement()
    return {
        "method": result.options.uncertainty,
        "confidence": level,
        **({"held_parameters": held} if held else {}),
        "parameters": per_parameter,
        "correlation": {
            "parameters": list(result.free_names),
            "matrix": [[round(float(v), 6) for v in row] for row in result.correlation],
        },
    }


def fitted_parameter_set(
    result: FitResult, prov: dict[str, Any], dataset_names: list[str]
) -> ParameterSet:
    """The fitted parameters as a ``ParameterSet`` carrying ``prov`` and ``uncertainty``,
    titled by the fitted recordings ``dataset_names``."""
    values = result.parameters.values
    return ParameterSet(
        variant=result.variant,
        values=dict(values),
        title=f"{result.variant} fitted to {', '.join(dataset_names)}",
        source=f"hframe-id fit {prov['fit_id']}",
        references=list(result.initial.references),
        notes=f"Fitted by multiple shooting from {prov['initial_source']}.",
        provenance=prov,
        uncertainty=uncertainty(result),
    )


def write_parameter_file(
    result: FitResult,
    recordings: list[Recording],
    dataset_paths: list[Path],
    initial_path: Path | None,
    out_dir: Path,
    when: datetime | None = None,
) -> tuple[str, Path | None]:
    """Write ``<out_dir>/<fit id>.yaml`` for a successful fit; returns (fit id, path or None).

    A failed fit gets an id (for its report) but no parameter file. An existing file is never
    overwritten (``ParameterFileError``).
    """
    when = when or datetime.now(UTC)
    fit_id = unused_fit_id(
        out_dir, make_fit_id(result.variant, [sha256_file(p) for p in dataset_paths], when)
    )
    if not result.success:
        return fit_id, None
    prov = provenance(result, recordings, dataset_paths, initial_path, fit_id, when)
    params = fitted_parameter_set(result, prov, [p.name for p in dataset_paths])
    path = out_dir / f"{fit_id}.yaml"
    if path.exists():
        raise FitError(f"{path}: a fit with this id exists already; not overwriting it")
    return fit_id, save_parameter_file(params, path)
