"""Recovery, multistart and bootstrap studies with their fits as tasks on Dask.

Every fit is one task, one thread, on the same clusters as ``hframe-id batch``
(``runner.dask_client``: a LocalCluster or ``--scheduler``); results arrive as they finish
(``as_completed``) and each is printed as a line.

- **Recovery / coverage** (``run_trials``): the trials of ``hframe_id.studies.recovery``
  (``python -m hframe_id.fleet.studies --seeds 0 1 2 3 --workers 2``).
- **Multistart** (``run_multistart``): the same recordings fitted from N starts drawn around
  the initial file (each free parameter times exp(N(0, spread)), inside the fit's bounds, which
  are fixed from the initial file so that every start solves the same problem); the best
  optimum, how many starts reached it and the spread of their estimates against the reported
  standard errors (``python -m hframe_id.fleet.studies multistart FILE ... --starts 8``).
- **Bootstrap** (``run_bootstrap``): B refits on resampled data, by experiments (recordings
  drawn with replacement) or parametric (the fitted model's simulated outputs plus fresh
  sensor noise, ``simulate_recording``); the bootstrap std and percentile 95 % interval of
  each parameter beside the fit's own (``python -m hframe_id.fleet.studies bootstrap FILE ...``).

Recordings travel to the workers as paths (like the batch's manifests: on a multi-machine
cluster every worker needs them at the same absolute path).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from distributed import Client, as_completed

from hframe_id.errors import HframeIdError, OptionError
from hframe_id.fitting.options import FitOptions
from hframe_id.fleet.keys import batch_options_for
from hframe_id.fleet.runner import dask_client
from hframe_id.studies.recovery import Trial, run_trial

#: Two optima whose costs (chi^2 / 2, noise-std units) differ by less than this are the same
#: optimum: 0.5 is one unit of chi^2, a log-likelihood difference far below what any test
#: could tell apart (the 95 % likelihood-ratio threshold for one parameter is 3.84 / 2).
SAME_OPTIMUM_COST = 0.5
#: ... plus this relative part, for the solver's round-off on large costs (mismatch fits).
SAME_OPTIMUM_RELATIVE = 1e-6
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


# --- tasks (run on the workers) -------------------------------------------------------------


def _read(paths: Sequence[str]) -> list:
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
    noise = result.diagnostics.get("noise", {})
    return FitOutcome(
        index,
        "ok" if result.success else "failed",
        result.message,
        float(result.cost),
        noise.get("method", ""),
        _concentrated_objective(data, noise.get("channels", {})),
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
    residual rms), in the cost's units (chi^2 / 2): sum_j N_j ln(rms_j / sensor std_j) + N / 2.
    Fits whose noise levels were estimated (model mismatch) weigh their residuals each with
    their own levels, so their costs are not comparable; this is."""
    total = 0.0
    for name, c in channels.items():
        n = sum(
            int(np.count_nonzero(rec.valid[:, rec.output_names.index(name)]))
            for rec in recordings
            if name in rec.output_names
        )
        total += n * (math.log(c["residual_rms"] / c["sensor_std"]) + 0.5)
    return total if channels else math.nan


def multistart_task(
    index: int, paths: Sequence[str], initial, start: dict[str, float], options: FitOptions
) -> FitOutcome:
    """Fit the recordings at ``paths`` from ``initial`` with the free values ``start``."""
    recordings = _read(paths)
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
    recordings = _read(paths)
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


# --- studies (run on the client) ------------------------------------------------------------


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
    from hframe_id.fitting.problem import resolve_free
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
    recordings = _read(resolved)  # unreadable or not a recording: LogFormatError, here
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
        p0 = initial.values[name]
        if built.parameters[built.parameter_names.index(name)].signed:
            bounds[name] = (p0 - f * abs(p0), p0 + f * abs(p0)) if p0 else (-f, f)
        else:
            bounds[name] = (p0 / f, p0 * f)
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


# --- command line ---------------------------------------------------------------------------


def _outcome_line(o: FitOutcome, what: str) -> str:
    label = "fit of the data" if o.index < 0 else f"{what} {o.index:3d}"
    picks = f" recordings {list(o.recordings)}" if o.recordings else ""
    return (
        f"{label}: {o.status} cost {o.cost:.6g}"
        + (f" (noise {o.noise}, concentrated {o.objective:.8g})" if o.noise == "estimated" else "")
        + f" it {o.iterations} "
        f"{o.wall_time_s:.1f} s{picks} {o.message}"
    )


def _table(header: list[str], rows: list[list[str]]) -> str:
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
    lines = [header, ["-" * w for w in widths], *rows]
    return "\n".join("  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in lines)


def _g(x: float) -> str:
    return f"{x:.5g}"


def _print_multistart(summary: dict[str, Any], outcomes: Sequence[FitOutcome]) -> None:
    status = ", ".join(f"{n} {s}" for s, n in summary["by_status"].items() if n)
    print(f"{summary['starts']} starts: {status}")
    if summary["best"] is None:
        print("no start converged")
        return
    by = "cost" if summary["compared_by"] == "cost" else "concentrated -log likelihood"
    print(
        f"best optimum: start {summary['best']}, {by} {summary['best_value']:.8g}; reached by "
        f"{len(summary['reached'])} of {summary['starts']} starts (within "
        f"{summary['tolerance']:.3g} of the best: one unit of chi^2)"
    )
    if summary["above_best"]:
        above = ", ".join(f"{c:.4g}" for c in summary["above_best"])
        print(f"other converged starts, {by} above the best: {above}")
    rows = [
        [name, p["unit"], _g(p["best"]), _g(p["std_error"]), _g(p["spread_std"]),
         f"{p['spread_over_std_error']:.3g}", _g(p["min"]), _g(p["max"])]
        for name, p in summary["parameters"].items()
    ]  # fmt: skip
    header = ["parameter", "unit", "best", "std error", "spread (std)", "spread/se", "min", "max"]
    print("over the starts that reached the best optimum:")
    print(_table(header, rows))


def _print_bootstrap(summary: dict[str, Any], method: str) -> None:
    status = ", ".join(f"{n} {s}" for s, n in summary["by_status"].items() if n)
    print(f"fit of the data: {summary['fit']['status']}, cost {summary['fit']['cost']:.8g}")
    print(f"{summary['replicates']} {method} bootstrap replicates: {status}")
    rows = [
        [name, p["unit"], _g(p["estimate"]), _g(p["std_error"]), _g(p["bootstrap_std"]),
         f"{p['bootstrap_over_std_error']:.3g}", f"[{_g(p['ci95'][0])}, {_g(p['ci95'][1])}]",
         f"[{_g(p['bootstrap_ci95'][0])}, {_g(p['bootstrap_ci95'][1])}]"]
        for name, p in summary["parameters"].items()
    ]  # fmt: skip
    header = ["parameter", "unit", "estimate", "std error", "bootstrap std", "boot/se",
              "fit 95 % interval", "bootstrap 95 % interval"]  # fmt: skip
    print(_table(header, rows))


def _study_parser(action: str) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=f"python -m hframe_id.fleet.studies {action}",
        description=(
            "Fit the recordings from N starts drawn around the initial file, one Dask task "
            "each; print each start, the best optimum, how many starts reached it and the "
            "spread of their estimates against the std errors."
            if action == "multistart"
            else "Fit the recordings, then refit B resampled data sets, one Dask task each; "
            "print the bootstrap std and 95 % interval per parameter beside the fit's own."
        ),
    )
    parser.add_argument("recordings", nargs="+", metavar="RECORDING", help="recordings (.mcap)")
    parser.add_argument("--initial", metavar="FILE", help="start parameter file "
                        "(default: the model's reference file, Table 4.2 / 2.3)")  # fmt: skip
    parser.add_argument("--model", help="model to fit (default: the initial file's variant)")
    parser.add_argument("--free", nargs="+", metavar="NAME", help="free parameters or patterns")
    if action == "multistart":
        parser.add_argument("--starts", type=int, default=8, metavar="N")
        parser.add_argument("--spread", type=float, default=0.2,
                            help="start = initial x exp(N(0, SPREAD)) (default 0.2)")  # fmt: skip
    else:
        parser.add_argument("--replicates", type=int, default=20, metavar="B")
        parser.add_argument("--method", choices=METHODS, help="resample the recordings "
                            "(default with several) or simulate the fit with fresh sensor "
                            "noise (default with one)")  # fmt: skip
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask cluster")
    parser.add_argument("--workers", type=int, metavar="N", help="LocalCluster worker processes")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead")
    return parser


def _study_main(action: str, argv: Sequence[str]) -> int:
    args = _study_parser(action).parse_args(argv)
    out = sys.stderr if args.json else sys.stdout
    try:
        if args.workers is not None and args.workers < 1:
            raise OptionError(f"--workers must be >= 1, got {args.workers}")
        setup = study_setup(args.recordings, args.initial, args.model, args.free)
        connect = lambda: dask_client(args.scheduler, args.workers)  # noqa: E731
        if action == "multistart":
            outcomes = run_multistart(
                connect, setup, args.starts, spread=args.spread, seed=args.seed,
                on_outcome=lambda o: print(_outcome_line(o, "start"), file=out, flush=True),
            )  # fmt: skip
            summary = summarize_multistart(outcomes)
            if not args.json:
                _print_multistart(summary, outcomes)
        else:
            fit, outcomes, method = run_bootstrap(
                connect, setup, args.replicates, method=args.method, seed=args.seed,
                on_outcome=lambda o: print(_outcome_line(o, "replicate"), file=out, flush=True),
            )  # fmt: skip
            summary = {"method": method, **summarize_bootstrap(fit, outcomes)}
            if not args.json:
                _print_bootstrap(summary, method)
    except HframeIdError as err:
        print(f"hframe-id: error: {err}", file=sys.stderr)
        return 2
    if args.json:
        summary["outcomes"] = [dataclasses.asdict(o) for o in outcomes]
        print(json.dumps(summary, indent=2, default=float))
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m hframe_id.fleet.studies [recovery] | multistart | bootstrap ...``: run a
    study's fits on a Dask cluster and print its table (or ``--json``); exit status 2 on
    bad input."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] in ("multistart", "bootstrap"):
        return _study_main(argv[0], argv[1:])
    if argv and argv[0] == "recovery":
        argv = argv[1:]
    parser = argparse.ArgumentParser(
        prog="python -m hframe_id.fleet.studies [recovery]",
        epilog="Also: 'multistart RECORDING ...' and 'bootstrap RECORDING ...' (see their --help).",
    )
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
