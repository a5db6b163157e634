"""Recovery, multistart and bootstrap studies with their fits as tasks on Dask.

Every fit is one task, one thread, on the same clusters as ``hframe-id batch``
(``runner.dask_client``: a LocalCluster or ``--scheduler``); results arrive as they finish
(``as_completed``) and each is printed as a line.

- **Recovery / coverage** (``run_trials``): the trials of ``studies.recovery``
  (``python -m studies.fleet --seeds 0 1 2 3 --workers 2``).
- **Multistart** (``run_multistart``): the same recordings fitted from N starts drawn around
  the initial file (each free parameter times exp(N(0, spread)), inside the fit's bounds, which
  are fixed from the initial file so that every start solves the same problem); the best
  optimum, how many starts reached it and the spread of their estimates against the reported
  standard errors (``python -m studies.fleet multistart FILE ... --starts 8``).
- **Bootstrap** (``run_bootstrap``): B refits on resampled data, by experiments (recordings
  drawn with replacement) or parametric (the fitted model's simulated outputs plus fresh
  sensor noise, ``simulate_recording``); the bootstrap std and percentile 95 % interval of
  each parameter beside the fit's own (``python -m studies.fleet bootstrap FILE ...``).

Recordings travel to the workers as paths (like the batch's manifests: on a multi-machine
cluster every worker needs them at the same absolute path).
"""

from studies.fleet.cli import main
from studies.fleet.runs import (
    StudySetup,
    draw_starts,
    run_bootstrap,
    run_multistart,
    run_trials,
    study_setup,
    summarize_bootstrap,
    summarize_multistart,
)
from studies.fleet.tasks import FitOutcome, bootstrap_task, multistart_task

__all__ = [
    "FitOutcome",
    "StudySetup",
    "bootstrap_task",
    "draw_starts",
    "main",
    "multistart_task",
    "run_bootstrap",
    "run_multistart",
    "run_trials",
    "study_setup",
    "summarize_bootstrap",
    "summarize_multistart",
]
