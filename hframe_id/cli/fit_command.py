"""``hframe-id fit``: identify a model's parameters from MCAP recordings (multiple shooting)."""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
import warnings
from contextlib import nullcontext
from pathlib import Path
from typing import TYPE_CHECKING

from hframe_id.cli.fit_arguments import HelpFormatter, add_fit_arguments
from hframe_id.cli.fit_options import fit_options
from hframe_id.cli.outputs import check_dir, check_distinct, check_input
from hframe_id.errors import FitError, ModelError, OptionError
from hframe_id.figure_drawers import InlineDrawer, ProcessDrawer
from hframe_id.fitting.options import FitOptions
from hframe_id.resources import datasets_dir

if TYPE_CHECKING:  # the fitting itself (CasADi, SciPy) is imported when a fit runs
    from hframe_id.fitting import FitResult
    from hframe_id.parameters import ParameterSet
    from hframe_id.recordings.recording import Recording
    from hframe_id.validation.cross_validation import LeaveOneOutTable

#: Where bare recording names are looked up: the working directory's datasets/, then the
#: shipped datasets/ (the checkout's, or an installed package's).
DATASETS_DIRS = (Path("datasets"), datasets_dir())


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
        formatter_class=HelpFormatter,
    )
    add_fit_arguments(parser)
    parser.set_defaults(handler=run)


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


def _recorded_variant(path: Path, recording: Recording) -> str:
    """The model variant ``recording`` (read from ``path``) names in ``rig.variant``, which
    must be one this hframe-id knows or a model file declared: the model a fit without
    ``--model`` fits."""
    from hframe_id.models import declaration

    try:
        declaration(recording.variant)
    except ModelError as err:
        raise ModelError(f"{path}: rig.variant: {err}") from None
    return recording.variant


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
    from hframe_id.simulation.integrators import check_simulable

    model = args.model or (args.loaded_models[0] if len(args.loaded_models) == 1 else None)
    if model:
        # A start of another variant fails before the recordings are read.
        initial, initial_path = _initial(args, model)
    paths = [resolve_dataset(name) for name in args.files]
    check_distinct(paths, "recording")
    recordings = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for path in paths:
            recordings.append(read_recording(path))
    for warning in caught:
        print(f"hframe-id: warning: {warning.message}", file=sys.stderr)
    variant = model or _recorded_variant(paths[0], recordings[0])
    if not model:
        initial, initial_path = _initial(args, variant)
    options = options.for_model(variant)
    start_source = f"--initial {initial_path}" if args.initial else str(initial_path)
    check_simulable(initial, recordings[0].sample_period_s, start_source)
    if args.known:
        from hframe_id.parameters import load_parameter_file

        known = tuple(load_parameter_file(Path(p), variant=variant) for p in args.known)
        for path, point in zip(args.known, known, strict=True):
            check_simulable(point, recordings[0].sample_period_s, f"--known {path}")
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
            from hframe_id.fitting.structure_choice import refit_setup

            fold_start, fold_options = refit_setup(result, initial, options)
            cross_validation = _cross_validate(recordings, fold_start, fold_options, args.quiet)
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
        from hframe_id.cli import json_output

        print(json_output.text(fit_summary(result, fit_id, parameter_file, report)))
    if not result.success:
        print(
            f"hframe-id: fit failed: {result.message}; no parameter file written", file=sys.stderr
        )
        return 1
    return 0
