"""A batch fit's identity and options: what makes two fits the same fit.

Light on imports (no solver, no plotting), so that a re-run with every fit stored is quick.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path
from typing import Any

from hframe_id.digests import sha256_file
from hframe_id.fitting.options import FitOptions
from hframe_id.fleet.manifest import FitJob

#: FitOptions fields that do not change a fit's result, left out of its key.
_NOT_IN_KEY = ("verbose", "progress", "threads")


def batch_options(job: FitJob) -> FitOptions:
    """The options of a batch fit: the model's fit defaults, ``job.free``, one thread (a
    worker runs one fit at a time; parallelism comes from workers), no progress output."""
    return batch_options_for(job.model, job.free)


def batch_options_for(model: str, free: tuple[str, ...] | None) -> FitOptions:
    """The options of a batch fit of ``model``: its declared fit defaults, ``free`` (None:
    the model's default free set), one thread, no progress output."""
    return FitOptions(free=free, threads=1, verbose=0).for_model(model)


def job_key(job: FitJob, options: FitOptions, digests: list[str]) -> str:
    """The fit's identity in the store: sha256 of the recordings' sha256, the model, the
    initial file's sha256 and every option that changes the result."""
    fields = {
        name: value
        for name, value in dataclasses.asdict(options).items()
        if name not in _NOT_IN_KEY
    }
    identity = {
        "recordings": digests,
        "model": job.model,
        "initial": sha256_file(job.initial),
        "options": fields,
    }
    text = json.dumps(identity, sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()


def base_row(job: FitJob, key: str, digests: list[str]) -> dict[str, Any]:
    """The columns every row has, whatever the fit's outcome."""
    return {
        "key": key,
        "rig": job.rig,
        "run_time": job.time,
        "entry": job.entry,
        "model": job.model,
        "recordings": ";".join(str(p) for p in job.recordings),
        "recordings_sha256": ";".join(digests),
        "initial": str(job.initial),
        "free": ",".join(job.free) if job.free else "",
    }


def staged_folder(out_dir: Path, key: str) -> Path:
    """Where the fit of ``key`` writes its files until its row is stored (``job.run_job``,
    ``runner.place_files``): a hidden folder in ``out_dir`` (the same file system, so that
    its files are renamed into place)."""
    return out_dir / f".staged-{key[:20]}"
