"""``python -m studies.fleet recovery|multistart|bootstrap``: options, progress
lines, tables and ``--json``."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np

from hframe_id.errors import HframeIdError, OptionError
from hframe_id.fleet.runner import dask_client
from studies.fleet.runs import (
    run_bootstrap,
    run_multistart,
    run_trials,
    study_setup,
    summarize_bootstrap,
    summarize_multistart,
)
from studies.fleet.tasks import METHODS, FitOutcome
from studies.recovery import Trial


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
        prog=f"python -m studies.fleet {action}",
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
    """``python -m studies.fleet [recovery] | multistart | bootstrap ...``: run a
    study's fits on a Dask cluster and print its table (or ``--json``); exit status 2 on
    bad input."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] in ("multistart", "bootstrap"):
        return _study_main(argv[0], argv[1:])
    if argv and argv[0] == "recovery":
        argv = argv[1:]
    parser = argparse.ArgumentParser(
        prog="python -m studies.fleet [recovery]",
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
