"""The studies' fits as Dask tasks (run on the workers): a fit of paths and parameters
returning a ``FitOutcome``; multistart and bootstrap tasks."""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from hframe_id.fitting.options import FitOptions

#: How a bootstrap resamples: recordings with replacement, or the fit's simulation plus noise.
METHODS = ("experiments", "parametric")


@dataclass
class FitOutcome:
    """One fit of a study: a start of a multistart or a bootstrap replicate (or the fit
    itself, ``index`` -1). ``status``: ``ok``, ``failed`` (the solver's verdict) or ``error``
    (an exception; ``message`` says which). Estimates, std errors, intervals in SI by name."""

    index: int
    status: str
    message: str
    cost: float = math.nan
    noise: str = ""
    objective: float = math.nan
    estimates: dict[str, float] = field(default_factory=dict)
    std_errors: dict[str, float] = field(default_factory=dict)
    ci95: dict[str, tuple[float, float]] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    start: dict[str, float] = field(default_factory=dict)
    recordings: tuple[int, ...] = ()
    iterations: int = 0
    wall_time_s: float = 0.0

    @property
    def ok(self) -> bool:
        """True when the fit succeeded."""
        return self.status == "ok"


def read_recordings(paths: Sequence[str]) -> list:
    """The recordings at ``paths``, read on a worker (their warnings, already shown on the
    client by ``study_setup``, silenced)."""
    from hframe_id.recordings import read_recording

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return [read_recording(p) for p in paths]


def _fit(index, data, params, options, **extra) -> FitOutcome:
    """Fit, never raise: an exception is an ``error`` outcome (one bad fit never stops a
    study), like ``hframe_id.fleet.job.run_job``."""
    from hframe_id.fitting import fit_recordings

    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = fit_recordings(data, params, options)
    except Exception as err:  # the fit's outcome, not the study's end
        return FitOutcome(
            index, "error", f"{type(err).__name__}: {err}", wall_time_s=time.perf_counter() - t0
        )
    free = {n: e for n, e in result.estimates.items() if e.free}
    noise = result.diagnostics.noise
    return FitOutcome(
        index,
        "ok" if result.success else "failed",
        result.message,
        float(result.cost),
        noise.method,
        _concentrated_objective(data, noise.channels),
        {n: float(e.estimate) for n, e in free.items()},
        {n: float(e.std_error) for n, e in free.items()},
        {n: (float(e.ci95[0]), float(e.ci95[1])) for n, e in free.items()},
        {n: e.unit for n, e in free.items()},
        iterations=int(result.iterations),
        wall_time_s=time.perf_counter() - t0,
        **extra,
    )


def _concentrated_objective(recordings, channels: dict) -> float:
    """-log likelihood with each channel's noise std at its maximum-likelihood value (the
    residual rms), in the cost's units (chi^2 / 2): sum_j N_j ln(rms_j / sensor std_j) + N / 2;
    ``channels``: each channel's ``noise_rounds.ChannelNoise`` by name. Fits whose noise
    levels were estimated (model mismatch) weigh their residuals each with their own levels,
    so their costs are not comparable; this is."""
    total = 0.0
    for name, c in channels.items():
        n = sum(
            int(np.count_nonzero(rec.valid[:, rec.output_names.index(name)]))
            for rec in recordings
            if name in rec.output_names
        )
        total += n * (math.log(c.residual_rms / c.sensor_std) + 0.5)
    return total if channels else math.nan


def multistart_task(
    index: int, paths: Sequence[str], initial, start: dict[str, float], options: FitOptions
) -> FitOutcome:
    """Fit the recordings at ``paths`` from ``initial`` with the free values ``start``."""
    recordings = read_recordings(paths)
    return _fit(index, recordings, initial.replace_values(**start), options, start=dict(start))


def bootstrap_task(
    index: int,
    paths: Sequence[str],
    initial,
    options: FitOptions,
    picks: Sequence[int] | None = None,
    fitted=None,
    seed: int = 0,
) -> FitOutcome:
    """One replicate: the recordings ``picks`` (by experiments), or, with ``fitted``, every
    recording's inputs simulated through the ``fitted`` parameters with fresh sensor noise
    (parametric; noise seeded by ``seed``). Fitted from ``initial``. ``index`` -1 with
    neither: the fit of the data themselves."""
    recordings = read_recordings(paths)
    if fitted is not None:
        from hframe_id.recordings.simulated import simulate_recording

        recordings = [
            simulate_recording(
                fitted,
                rec.inputs,
                rec.sample_period_s,
                seed=seed * 1000 + i,
                experiment={**rec.experiment, "bootstrap": index},
            )
            for i, rec in enumerate(recordings)
        ]
        picks = None
    elif picks is not None:
        recordings = [recordings[i] for i in picks]
    return _fit(index, recordings, initial, options, recordings=tuple(picks or ()))
