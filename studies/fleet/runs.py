"""The studies on the client: draw the starts or replicates, submit the tasks, gather the
outcomes as they finish, summarize."""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from distributed import Client, as_completed

from hframe_id.errors import OptionError
from hframe_id.fitting.options import FitOptions
from hframe_id.fleet.keys import batch_options_for
from studies.fleet.tasks import (
    METHODS,
    FitOutcome,
    bootstrap_task,
    multistart_task,
    read_recordings,
)
from studies.recovery import Trial, run_trial

#: Two optima whose costs (chi^2 / 2, noise-std units) differ by less than this are the same
#: optimum: 0.5 is one unit of chi^2, a log-likelihood difference far below what any test
#: could tell apart (the 95 % likelihood-ratio threshold for one parameter is 3.84 / 2).
SAME_OPTIMUM_COST = 0.5
#: ... plus this relative part, for the solver's round-off on large costs (mismatch fits).
SAME_OPTIMUM_RELATIVE = 1e-6


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


@dataclass
class StudySetup:
    """What every fit of a study shares: recordings (paths), the start, the options."""

    paths: tuple[str, ...]
    initial: Any  # ParameterSet
    options: FitOptions
    free: tuple[str, ...]
    bounds: dict[str, tuple[float, float]]


def study_setup(
    paths: Sequence[str | Path],
    initial_file: str | Path | None,
    model: str | None = None,
    free: Sequence[str] | None = None,
) -> StudySetup:
    """Check the inputs (``HframeIdError`` naming the file or name at fault) and fix the
    options: the model's fit defaults, one thread (``keys.batch_options_for``), and every free
    parameter's bounds set from the initial file (the fit's default bounds, p0 x/÷
    ``bound_factor``, or p0 -/+ ``bound_factor`` |p0| for signed ones), so that a start drawn
    elsewhere solves the same problem."""
    from hframe_id.fitting.problem import default_bounds, resolve_free
    from hframe_id.models import build_model, declaration
    from hframe_id.parameters import load_parameter_file

    if not paths:
        raise OptionError("no recordings given")
    resolved = []
    for p in paths:
        path = Path(p)
        if not path.is_file():
            raise OptionError(f"{path}: no such recording")
        resolved.append(str(path.resolve()))
    if initial_file is not None and not Path(initial_file).is_file():
        raise OptionError(f"{initial_file}: no such parameter file")
    recordings = read_recordings(resolved)  # unreadable or not a recording: LogFormatError, here
    if model is None:
        model = load_parameter_file(initial_file).variant if initial_file else recordings[0].variant
    built = build_model(model)  # unknown model: ModelError naming the valid ones
    if initial_file is None:
        initial_file = declaration(model).reference_file
        if initial_file is None:
            raise OptionError(f"model {model!r} declares no reference file; give --initial")
    initial = load_parameter_file(initial_file, variant=model)  # another model's file: error
    options = batch_options_for(model, tuple(free) if free else None)
    names = tuple(resolve_free(built, options))
    bounds = dict(options.bounds)
    f = options.bound_factor
    for name in names:
        if name in bounds:
            continue
        kind = built.parameters[built.parameter_names.index(name)].kind
        value = initial.values[name]
        bounds[name] = default_bounds(kind, value, f, linear=value == 0)
    options = dataclasses.replace(options, bounds=bounds)
    return StudySetup(tuple(resolved), initial, options, names, bounds)


def draw_starts(
    setup: StudySetup, n: int, spread: float, rng: np.random.Generator
) -> list[dict[str, float]]:
    """``n`` starts: every free parameter of the initial file times exp(N(0, ``spread``))
    (signed ones plus N(0, spread) |p0|), clipped to 1 % inside its bounds (in log scale)."""
    starts = []
    for _ in range(n):
        start = {}
        for name in setup.free:
            p0 = setup.initial.values[name]
            low, high = setup.bounds[name]
            if low > 0:
                value = p0 * math.exp(rng.normal(0.0, spread))
                margin = 0.01 * math.log(high / low)
                value = min(max(value, low * math.exp(margin)), high / math.exp(margin))
            else:
                value = p0 + abs(p0 or 1.0) * rng.normal(0.0, spread)
                margin = 0.01 * (high - low)
                value = min(max(value, low + margin), high - margin)
            start[name] = value
        starts.append(start)
    return starts


def _gather(client, futures, on_outcome) -> list[FitOutcome]:
    outcomes = []
    try:
        for future in as_completed(futures):
            try:
                outcome = future.result()
            except Exception as err:  # the task itself died (its workers killed)
                outcome = FitOutcome(futures[future], "error", f"{type(err).__name__}: {err}")
            outcomes.append(outcome)
            if on_outcome is not None:
                on_outcome(outcome)
    except KeyboardInterrupt:
        client.cancel(list(futures))
        raise
    return sorted(outcomes, key=lambda o: o.index)


def run_multistart(
    connect: Callable[[], AbstractContextManager[Client]],
    setup: StudySetup,
    n_starts: int,
    *,
    spread: float = 0.2,
    seed: int = 0,
    on_outcome: Callable[[FitOutcome], None] | None = None,
) -> list[FitOutcome]:
    """Fit ``setup``'s recordings from ``n_starts`` starts (``draw_starts``, seeded), one task
    each on the cluster ``connect`` gives; the outcomes in start order."""
    if n_starts < 1:
        raise OptionError(f"--starts must be >= 1, got {n_starts}")
    if not spread > 0:
        raise OptionError(f"--spread must be > 0, got {spread}")
    starts = draw_starts(setup, n_starts, spread, np.random.default_rng(seed))
    with connect() as client:
        futures = {
            client.submit(
                multistart_task,
                i,
                setup.paths,
                setup.initial,
                start,
                setup.options,
                pure=False,
                key=f"multistart-{seed}-{i}-{time.time_ns()}",
            ): i
            for i, start in enumerate(starts)
        }
        return _gather(client, futures, on_outcome)


def summarize_multistart(outcomes: Sequence[FitOutcome]) -> dict[str, Any]:
    """The best optimum (lowest cost among the ``ok`` starts), the starts that reached it
    (cost within ``SAME_OPTIMUM_COST`` + ``SAME_OPTIMUM_RELATIVE`` x best of it), and per
    parameter: the best estimate, its std error, and the std and range of the estimates over
    the starts that reached it (``spread / std error``: well below 1 means every start found
    the same point, to within the noise's own uncertainty)."""
    ok = [o for o in outcomes if o.ok]
    # Costs compare only with the noise levels the sensor's in every fit; else the
    # concentrated likelihood (``_concentrated_objective``), in the same units.
    by = "cost" if all(o.noise == "sensor" for o in ok) else "objective"
    summary: dict[str, Any] = {
        "starts": len(outcomes),
        "compared_by": by,
        "by_status": {s: sum(o.status == s for o in outcomes) for s in ("ok", "failed", "error")},
    }
    if not ok:
        summary.update(best=None, reached=[], parameters={})
        return summary
    score = {o.index: getattr(o, by) for o in ok}
    best = min(ok, key=lambda o: score[o.index])
    tolerance = SAME_OPTIMUM_COST + SAME_OPTIMUM_RELATIVE * abs(score[best.index])
    reached = [o for o in ok if score[o.index] - score[best.index] <= tolerance]
    parameters = {}
    for name, value in best.estimates.items():
        values = np.array([o.estimates[name] for o in reached])
        std = float(np.std(values, ddof=1)) if len(values) > 1 else 0.0
        se = best.std_errors[name]
        parameters[name] = {
            "unit": best.units[name],
            "best": value,
            "std_error": se,
            "spread_std": std,
            "spread_over_std_error": std / se if se > 0 else math.nan,
            "min": float(values.min()),
            "max": float(values.max()),
        }
    summary.update(
        best=best.index,
        best_cost=best.cost,
        best_value=score[best.index],
        tolerance=tolerance,
        reached=[o.index for o in reached],
        above_best=sorted(score[o.index] - score[best.index] for o in ok if o not in reached),
        parameters=parameters,
    )
    return summary


def run_bootstrap(
    connect: Callable[[], AbstractContextManager[Client]],
    setup: StudySetup,
    n_replicates: int,
    *,
    method: str | None = None,
    seed: int = 0,
    on_outcome: Callable[[FitOutcome], None] | None = None,
) -> tuple[FitOutcome, list[FitOutcome], str]:
    """The fit of the data (one task; by experiments alongside the replicates, parametric
    before them) and ``n_replicates`` refits on resampled data, one task each: ``method``
    ``"experiments"`` (the recordings drawn with replacement; the default with several) or
    ``"parametric"`` (the fit's parameters simulated with fresh sensor noise; the default
    with one recording). Seeded by ``seed``. Returns (the fit, the replicates in
    order, the method)."""
    if n_replicates < 2:
        raise OptionError(f"--replicates must be >= 2, got {n_replicates}")
    method = method or ("experiments" if len(setup.paths) > 1 else "parametric")
    if method not in METHODS:
        raise OptionError(f"--method must be one of {', '.join(METHODS)}, got {method!r}")
    if method == "experiments" and len(setup.paths) < 2:
        raise OptionError("--method experiments needs two or more recordings (or: parametric)")
    rng = np.random.default_rng(seed)
    tag = f"{seed}-{time.time_ns()}"
    with connect() as client:
        fit_future = client.submit(
            bootstrap_task, -1, setup.paths, setup.initial, setup.options, key=f"fit-{tag}"
        )
        futures, fitted = {}, None
        if method == "parametric":  # the replicates need the fit; by experiments they do not
            fit = _gather(client, {fit_future: -1}, on_outcome)[0]
            if not fit.ok:
                raise OptionError(f"the fit of the data did not succeed ({fit.message}); no "
                                  "model to simulate for a parametric bootstrap")  # fmt: skip
            fitted = setup.initial.replace_values(**fit.estimates)
        else:
            futures[fit_future] = -1
        for b in range(n_replicates):
            picks = None
            if method == "experiments":
                picks = sorted(rng.integers(0, len(setup.paths), len(setup.paths)).tolist())
            replicate_seed = int(rng.integers(0, 2**31))
            future = client.submit(
                bootstrap_task,
                b,
                setup.paths,
                setup.initial,
                setup.options,
                picks,
                fitted,
                replicate_seed,
                pure=False,
                key=f"bootstrap-{tag}-{b}",
            )
            futures[future] = b
        outcomes = _gather(client, futures, on_outcome)
        if method == "experiments":
            fit, outcomes = outcomes[0], outcomes[1:]  # index -1 sorts first
        return fit, outcomes, method


def summarize_bootstrap(fit: FitOutcome, replicates: Sequence[FitOutcome]) -> dict[str, Any]:
    """Per parameter over the ``ok`` replicates: bootstrap std and percentile 95 % interval
    (2.5 and 97.5 % quantiles), beside the fit's estimate, std error and interval."""
    ok = [r for r in replicates if r.ok]
    parameters = {}
    for name, value in fit.estimates.items():
        values = np.array([r.estimates[name] for r in ok if name in r.estimates])
        enough = len(values) >= 2
        parameters[name] = {
            "unit": fit.units[name],
            "estimate": value,
            "std_error": fit.std_errors[name],
            "ci95": list(fit.ci95[name]),
            "bootstrap_std": float(np.std(values, ddof=1)) if enough else math.nan,
            "bootstrap_ci95": (
                [float(q) for q in np.percentile(values, [2.5, 97.5])]
                if enough
                else [math.nan, math.nan]
            ),
            "bootstrap_over_std_error": (
                float(np.std(values, ddof=1)) / fit.std_errors[name]
                if enough and fit.std_errors[name] > 0
                else math.nan
            ),
        }
    return {
        "fit": {"status": fit.status, "message": fit.message, "cost": fit.cost},
        "replicates": len(replicates),
        "by_status": {s: sum(r.status == s for r in replicates) for s in ("ok", "failed", "error")},
        "parameters": parameters,
    }
