"""``hframe-id fit``: identify a model's parameters from MCAP recordings (multiple shooting)."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
import warnings
from contextlib import nullcontext
from pathlib import Path
from typing import TYPE_CHECKING

from hframe_id.cli.fit_options import fit_options
from hframe_id.cli.numbers import add_number
from hframe_id.cli.outputs import check_dir, check_input
from hframe_id.errors import FitError, OptionError
from hframe_id.figure_drawers import InlineDrawer, ProcessDrawer
from hframe_id.fitting.link_options import CONSIDER_METHODS, CONTINUITY, UNCERTAINTY_METHODS
from hframe_id.fitting.options import NOISE_METHODS, FitOptions
from hframe_id.fitting.solvers import solver_names
from hframe_id.resources import datasets_dir

if TYPE_CHECKING:  # the fitting itself (CasADi, SciPy) is imported when a fit runs
    from hframe_id.fitting import FitResult
    from hframe_id.parameters import ParameterSet
    from hframe_id.recordings.recording import Recording
    from hframe_id.validation.cross_validation import LeaveOneOutTable

#: Where bare recording names are looked up: the working directory's datasets/, then the
#: shipped datasets/ (the checkout's, or an installed package's).
DATASETS_DIRS = (Path("datasets"), datasets_dir())


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows defaults, except empty ones and flags (their help says what happens)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        if action.default in (None, "", [], ()) or isinstance(action.default, bool):
            return action.help or ""
        return super()._get_help_string(action)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Register the ``fit`` subcommand."""
    parser = subparsers.add_parser(
        "fit",
        help="fit stiffness, friction and inertia to recordings (multiple shooting)",
        description=(
            "Fit a model's parameters to one or more MCAP recordings of the same rig, jointly, "
            "by multiple shooting in CasADi (Gauss-Newton on the lifted problem). Writes a "
            "versioned parameter file <fit id>.yaml (only if the fit succeeds) and a report "
            "<fit id>-report.md with plots to --out-dir; with several recordings the report "
            "has a leave-one-recording-out cross-validation table. A fit that converges but "
            "does not follow the data at the sensors' noise level (model mismatch) succeeds "
            "and says so. Exit status: 0 success, 1 the solver failed (report only), 2 bad "
            "input."
        ),
        formatter_class=_HelpFormatter,
    )
    _add_data_options(parser)
    _add_parameter_options(parser)
    _add_noise_options(parser)
    _add_transcription_options(parser)
    _add_strategy_options(parser)
    _add_convergence_options(parser)
    _add_statistics_options(parser)
    _add_output_options(parser)
    parser.set_defaults(handler=run)


def _add_data_options(parser: argparse.ArgumentParser) -> None:
    """The recordings and the start: ``files``, ``--initial``, ``--model``."""
    parser.add_argument(
        "files",
        nargs="+",
        metavar="FILE",
        help="MCAP recordings; a bare name is looked up in ./datasets/, then in the "
        "project's shipped datasets/",
    )
    parser.add_argument(
        "--initial",
        metavar="FILE",
        help="initial parameter file (default: the model's reference set, for the thesis's "
        "variants their table: one-axis: models/one-axis-table2.3.yaml, hframe-20: "
        "models/hframe-20-table3.1.yaml, hframe-8: models/hframe-8-table4.2.yaml)",
    )
    parser.add_argument(
        "--model",
        metavar="VARIANT",
        help="model variant to fit (one-axis, hframe-20, hframe-8, any `hframe-id models` "
        "lists, or one from --model-file; default: "
        "the model of the --model-file, else the recordings' rig variant); picks the default "
        "initial file",
    )


def _add_parameter_options(parser: argparse.ArgumentParser) -> None:
    """Which parameters are free and their bounds [SI units]."""
    parser.add_argument(
        "--free",
        metavar="NAMES",
        help="comma-separated parameter names or patterns to fit (e.g. 'k_*,J_M*'); default: "
        "every stiffness, mass, inertia, viscous and Coulomb friction parameter and g_2",
    )
    parser.add_argument(
        "--fix",
        metavar="NAMES",
        default="",
        help="comma-separated names or patterns to hold at their initial value",
    )
    parser.add_argument(
        "--bounds",
        metavar="NAME=LOW:HIGH",
        action="append",
        default=[],
        help="bounds of a free parameter (exact name, not a pattern) in SI units, both "
        "positive (parameters are fitted in log scale) and enclosing the initial value "
        "(repeatable)",
    )
    add_number(
        parser,
        "--bound-factor",
        float,
        above=1,
        default=10.0,
        help="default bounds: initial value divided / multiplied by this",
    )


def _add_noise_options(parser: argparse.ArgumentParser) -> None:
    """How the residuals are weighted: the channels' noise std [rad or m]."""
    parser.add_argument(
        "--channel-std",
        metavar="OUTPUT=STD",
        action="append",
        default=[],
        help="noise std [rad or m] that weights an output's residuals (repeatable; outputs "
        "phi1, phi2, x, y for the H-frame, phi1, x for one-axis); default: "
        "encoder step/sqrt(12) and the rig's laser noise",
    )
    parser.add_argument(
        "--noise",
        choices=NOISE_METHODS,
        default=FitOptions.noise,
        help="channel weights: 'sensor' the sensors' noise (--channel-std or the rig's "
        "noise model); 'estimate' noise levels estimated from the residuals; 'auto' "
        "estimated when the model does not follow the data at the sensors' noise level",
    )


def _add_transcription_options(parser: argparse.ArgumentParser) -> None:
    """The solver of the all-window stages and the transcription it solves: sensor latency
    [samples], shooting intervals [samples], continuity, Coulomb smoothing, initial states."""
    parser.add_argument(
        "--solver",
        choices=solver_names(),
        default=FitOptions.solver,
        help="solver of the all-window stages: the condensed Gauss-Newton, or CasADi's "
        "IPOPT or SQP (nlpsol, exact Gauss-Newton Hessian) on the same transcription",
    )
    parser.add_argument(
        "--latency",
        action="append",
        default=[],
        metavar="OUTPUT=SAMPLES",
        help="whole samples a sensor lags the plant (repeatable, e.g. x=2 for a laser with "
        "2 ms read-out latency at 1 kHz); not estimated: in steady motion it looks like "
        "belt stretch",
    )
    add_number(
        parser,
        "--shooting-interval",
        int,
        at_least=1,
        metavar="SAMPLES",
        help="samples per shooting interval (a node every this many samples; default: the "
        "model's fit default, else 10)",
    )
    parser.add_argument(
        "--continuity",
        choices=CONTINUITY,
        help="'exact': the intervals join into one simulated trajectory (output error); "
        "'none': each interval starts from its own estimated state (prediction error on "
        "horizons of --shooting-interval samples, for plants whose simulation drifts). "
        "Default: the model's fit default, else 'exact'",
    )
    parser.add_argument(
        "--smoothing",
        metavar="LIN,ANG",
        help="final Coulomb smoothing velocities [m/s],[rad/s] (default: the model's 1e-3,1e-2)",
    )
    parser.add_argument(
        "--smoothing-schedule",
        metavar="F1,F2,...",
        default="1",
        help="continuation factors on the smoothing, decreasing to 1, applied in the "
        "moving-window stages; the default 1 is no continuation (measured worse on these "
        "records, docs/fitting.md)",
    )
    parser.add_argument(
        "--initial-state",
        choices=("auto", "rest", "estimate"),
        default="auto",
        help="each recording's initial state: at rest (every velocity zero and the belts "
        "unstretched, at the measured position, as validate and simulate start; the stages "
        "estimate the belt-free position, a last solve takes validate's) where "
        "the record's first 10 samples show rest, estimated where it starts in motion (auto); "
        "every one at rest; or every one estimated",
    )


def _add_strategy_options(parser: argparse.ArgumentParser) -> None:
    """The stages: zero-reachable friction, known points, the multistart portfolio, the start."""
    parser.add_argument(
        "--zero-reachable",
        default="",
        metavar="NAMES",
        help="comma-separated friction parameters fitted linearly from 0, which they may "
        "reach (the others are fitted in log scale, and a fit that ends with one on its lower "
        "bound is repeated with it reaching 0)",
    )
    parser.add_argument(
        "--known",
        action="append",
        default=[],
        metavar="FILE",
        help="a parameter file of the fitted model the fit must not end worse than (besides "
        "its start, the equation-error estimate and the model's reference files): ended "
        "worse, it continues from the best of them, or fails saying so; repeatable",
    )
    add_number(
        parser,
        "--starts",
        int,
        at_least=1,
        default=FitOptions.starts,
        metavar="N",
        help="a multistart portfolio: the fit from the start and from N-1 seeded draws "
        "around it (each free parameter x/÷2 at most), the best kept and how many starts "
        "reached it reported (default 1: the start only); N fits' time",
    )
    add_number(
        parser,
        "--start-seed",
        int,
        at_least=0,
        default=FitOptions.start_seed,
        metavar="S",
        help="seed of the portfolio's draws (default 0)",
    )
    parser.add_argument(
        "--start-as-given",
        action="store_true",
        help="begin from --initial even where the model's reference files or a --known file "
        "simulate the records (all starting at rest) better (default: from the best of them, "
        "said in the summary)",
    )
    parser.add_argument(
        "--no-first-stage",
        action="store_true",
        help="skip the equation-error start and the stages on the moving windows (start the "
        "full multiple-shooting problem directly from --initial)",
    )


def _add_convergence_options(parser: argparse.ArgumentParser) -> None:
    """When a stage has converged: iterations, step and defect tolerances; the tuning of the
    Gauss-Newton iteration and of the stages."""
    parser.add_argument(
        "--gauss-newton",
        action="append",
        default=[],
        metavar="SETTING=VALUE",
        help="a setting of the Gauss-Newton iteration (repeatable; GaussNewtonSettings in "
        "docs/api.md: trust region, node damping, watchdog, stall rules), recorded in the "
        "parameter file's provenance",
    )
    parser.add_argument(
        "--strategy",
        action="append",
        default=[],
        metavar="SETTING=VALUE",
        help="a setting of the stages (repeatable; StrategySettings in docs/api.md: "
        "intermediate tolerances, noise rounds, box widenings, restarts, holds; a tuple as "
        "comma-separated numbers), recorded in the parameter file's provenance",
    )
    add_number(
        parser,
        "--max-iterations",
        int,
        at_least=1,
        default=FitOptions.max_iterations,
        help="Gauss-Newton iterations per stage",
    )
    add_number(
        parser,
        "--step-tol",
        float,
        above=0,
        default=1e-6,
        help="converged when no parameter changes by more than this (relative)",
    )
    add_number(
        parser,
        "--defect-tol",
        float,
        above=0,
        default=1e-2,
        help="continuity defects at convergence, in noise units; a stage that can no "
        "longer decrease its cost is also accepted with defects below 2 noise std if the "
        "residuals are at the noise level (rms <= 1.5 std), and the largest defect is "
        "reported in the solver message",
    )


def _add_statistics_options(parser: argparse.ArgumentParser) -> None:
    """Identifiability, the misfit limit [noise std] and how standard errors are computed."""
    add_number(
        parser,
        "--identifiability-threshold",
        float,
        above=0,
        default=0.1,
        help="relative std error above which a parameter counts as not "
        "identified and is held at its initial value",
    )
    add_number(
        parser,
        "--max-misfit",
        float,
        above=0,
        default=None,
        help="a fit whose residual rms exceeds this many std of the sensors' noise (the "
        "rig's specification or --channel-std, never a level estimated from the residuals) "
        "fails (default: 5 for a fit weighted by the sensors' noise, no limit for one that "
        "estimated its noise levels under model mismatch)",
    )
    parser.add_argument(
        "--uncertainty",
        choices=UNCERTAINTY_METHODS,
        default="robust",
        help="how standard errors are computed",
    )
    parser.add_argument(
        "--consider-method",
        choices=CONSIDER_METHODS,
        default=FitOptions.consider_method,
        help="how the held parameters' prior uncertainty (+/-20 %%) enters: 'linear' (held, "
        "the intervals widened at the optimum), 'refit' (held, the fit repeated twice per held "
        "parameter at its value x exp(+/-0.2): slower, for effects that are not linear) or "
        "'prior' (estimated, with the prior as a penalty: maximum a posteriori)",
    )


def _add_output_options(parser: argparse.ArgumentParser) -> None:
    """Threads, cross-validation and what is written where (files, stderr, JSON on stdout)."""
    add_number(
        parser,
        "--threads",
        int,
        at_least=1,
        default=None,
        help="worker threads (default: the CPU count, at most 8)",
    )
    parser.add_argument(
        "--no-cross-validation",
        action="store_true",
        help="skip the leave-one-recording-out cross-validation of a fit of several "
        "recordings (it refits once per recording)",
    )
    parser.add_argument("--out-dir", default="fits", help="where the fit and report go")
    parser.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    parser.add_argument(
        "--no-plots", action="store_true", help="write the report without its figures (faster)"
    )
    parser.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object on stdout (success, fit id, files, every parameter with "
        "unit, std and 95 %% interval; docs/fitting-json.md); the summary goes to stderr",
    )


def resolve_dataset(name: str) -> Path:
    """The recording ``name``: as given, else in ./datasets/, then in the shipped datasets/.

    Raises FitError naming the folders looked in, OptionError for a recording that cannot
    be read (mode 000, or in a folder that cannot be searched).
    """
    path = Path(name)
    for candidate in (path, *(directory / name for directory in DATASETS_DIRS)):
        try:
            found = candidate.exists()
        except PermissionError as err:
            raise OptionError(f"{candidate}: cannot read ({err.strerror})") from None
        if found:
            return check_input(candidate)
    looked = ", ".join(f"{d}/" for d in DATASETS_DIRS)
    raise FitError(f"{name}: no such recording (also looked in {looked})")


def _initial(args: argparse.Namespace, variant: str) -> tuple[ParameterSet, Path]:
    """The start of the fit and its file, which must be of the fitted ``variant``."""
    from hframe_id.models import declaration
    from hframe_id.parameters import load_parameter_file

    if args.initial:
        path = Path(args.initial)
    elif declaration(variant).reference_file is not None:
        path = declaration(variant).reference_file
    else:
        raise FitError(f"model {variant!r} declares no reference parameter file; use --initial")
    return load_parameter_file(path, variant=variant), path


def _cross_validate(
    recordings: list[Recording], initial: ParameterSet, options: FitOptions, quiet: bool
) -> LeaveOneOutTable | None:
    """Leave-one-recording-out refits with the fit's options, a line per fold on stderr; None
    (with a warning) if a refit raises: the fit is kept without its cross-validation."""
    from hframe_id.validation.cross_validation import leave_one_out

    def announce(fold: int, folds: int, held_out: str) -> None:
        if not quiet:
            print(
                f"cross-validation {fold}/{folds}: fitting without {held_out}",
                file=sys.stderr,
                flush=True,
            )

    start = time.perf_counter()
    try:
        table = leave_one_out(
            recordings, initial, dataclasses.replace(options, verbose=0, progress=None), announce
        )
    except Exception as err:  # the fit stands without it
        print(
            f"hframe-id: warning: cross-validation failed ({type(err).__name__}: {err}); "
            "the fit is written without it",
            file=sys.stderr,
        )
        return None
    if not quiet:
        print(
            f"cross-validation: {len(recordings)} refits in {time.perf_counter() - start:.1f} s",
            file=sys.stderr,
        )
    return table


def _print_mismatch(result: FitResult, stream) -> None:
    """The model-mismatch statement and its per-channel table, if the fit estimated noise."""
    from hframe_id.fitting.report import mismatch_rows, mismatch_statement

    statement = mismatch_statement(result)
    if statement is None:
        return
    rows = mismatch_rows(result)
    widths = [max(len(row[k]) for row in rows) for k in range(len(rows[0]))]
    print(f"model mismatch: {statement}", file=stream)
    for row in rows:
        cells = (cell.ljust(width) for cell, width in zip(row, widths, strict=True))
        print("  ".join(cells).rstrip(), file=stream)


def _remove_made(out_dir: Path, created: bool) -> None:
    """Remove ``out_dir`` if this command ``created`` it and it is still empty."""
    if created and not any(out_dir.iterdir()):
        out_dir.rmdir()


def _write_outputs(
    result: FitResult,
    recordings: list[Recording],
    paths: list[Path],
    initial_path: Path,
    out_dir: Path,
    cross_validation: LeaveOneOutTable | None,
    drawer: InlineDrawer | ProcessDrawer | None = None,
) -> tuple[str, Path | None, Path | None]:
    """The parameter file (a successful fit only), then the report with its plots drawn by
    ``drawer`` (None: no plots). The parameter file is the fit's result: once written it is
    kept, and a failure of the report (which leaves nothing of itself) is a warning on
    stderr, the report then None. A failure before the parameter file leaves nothing (nor
    ``out_dir`` if this created it), and so does Ctrl-C or SIGTERM while the report is
    written: the user stopped the command, which then leaves none of its outputs."""
    from hframe_id.fitting.output import write_parameter_file
    from hframe_id.fitting.report import write_report

    created = not out_dir.exists()
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise FitError(f"--out-dir {out_dir}: cannot create it ({err.strerror})") from err
    try:
        fit_id, parameter_file = write_parameter_file(
            result, recordings, paths, initial_path, out_dir
        )
    except BaseException:
        _remove_made(out_dir, created)
        raise
    try:
        report = write_report(
            result,
            recordings,
            fit_id,
            parameter_file,
            out_dir,
            cross_validation,
            plots=drawer is not None,
            drawer=drawer,
        )
    except KeyboardInterrupt:
        if parameter_file is not None:
            parameter_file.unlink(missing_ok=True)
        _remove_made(out_dir, created)
        raise
    except Exception as err:  # the fit is kept: a report is a view of it
        print(
            f"hframe-id: warning: the report was not written ({type(err).__name__}: {err}); "
            + (f"the parameter file {parameter_file} is" if parameter_file else "nothing is"),
            "kept",
            file=sys.stderr,
        )
        report = None
    return fit_id, parameter_file, report


def _inputs(args: argparse.Namespace, options: FitOptions):
    """The recordings (``paths``, ``recordings``), the start (``initial``, ``initial_path``),
    the fitted ``variant`` and the options with the model's defaults, read and checked."""
    from hframe_id.recordings import read_recording

    model = args.model or (args.loaded_models[0] if len(args.loaded_models) == 1 else None)
    if model:
        # A start of another variant fails before the recordings are read.
        initial, initial_path = _initial(args, model)
    paths = [resolve_dataset(name) for name in args.files]
    recordings = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for path in paths:
            recordings.append(read_recording(path))
    for warning in caught:
        print(f"hframe-id: warning: {warning.message}", file=sys.stderr)
    variant = model or recordings[0].variant
    if not model:
        initial, initial_path = _initial(args, variant)
    options = options.for_model(variant)
    if args.known:
        from hframe_id.parameters import load_parameter_file

        known = tuple(load_parameter_file(Path(p), variant=variant) for p in args.known)
        options = dataclasses.replace(options, known_points=known)
    return paths, recordings, initial, initial_path, variant, options


def run(args: argparse.Namespace) -> int:
    """Run ``hframe-id fit``: fit, cross-validate, write the parameter file and the report.

    Exit status 0 on success, 1 if the fit failed (then no parameter file is written).
    """
    options = fit_options(args)
    out_dir = check_dir(args.out_dir, "--out-dir")
    # The figure worker starts first: it imports matplotlib while this process reads the
    # inputs and imports the fitter (both single-threaded; the solve uses every core).
    from hframe_id.fitting.report_figures import import_matplotlib

    with nullcontext() if args.no_plots else ProcessDrawer(import_matplotlib) as drawer:
        paths, recordings, initial, initial_path, variant, options = _inputs(args, options)
        if not args.quiet:
            total = sum(rec.n_samples for rec in recordings)
            print(
                f"fitting {variant} to {len(recordings)} recording(s), {total} samples, "
                f"starting from {initial_path}",
                file=sys.stderr,
            )
        from hframe_id.fitting import fit_recordings

        result = fit_recordings(recordings, initial, options)
        cross_validation = None
        if result.success and len(recordings) > 1 and not args.no_cross_validation:
            cross_validation = _cross_validate(recordings, initial, options, args.quiet)
            if cross_validation is not None:
                from hframe_id.fitting.jackknife import with_jackknife_intervals

                result = with_jackknife_intervals(result, cross_validation)
        fit_id, parameter_file, report = _write_outputs(
            result, recordings, paths, initial_path, out_dir, cross_validation, drawer
        )
    from hframe_id.fitting.report import incomplete_recordings
    from hframe_id.fitting.summary_json import fit_summary

    human = sys.stderr if args.json else sys.stdout
    print(result.summary(), file=human)
    for line in incomplete_recordings(recordings):
        print(f"incomplete recording: {line}", file=human)
    if held := result.held_statement():
        print(held, file=human)
    _print_mismatch(result, human)
    if parameter_file:
        print(f"parameter file: {parameter_file}", file=human)
    if report:
        print(f"report: {report}", file=human)
    if args.json:
        print(json.dumps(fit_summary(result, fit_id, parameter_file, report), indent=2))
    if not result.success:
        print(
            f"hframe-id: fit failed: {result.message}; no parameter file written", file=sys.stderr
        )
        return 1
    return 0
