"""``hframe-id validate``: judge parameter files on held-out recordings (MATLAB's ``compare``
and ``resid``): simulation fit, k-step-ahead prediction fit, residual correlation tests; and
the scores the literature uses: open-loop RMSE, inverse-model force error, closed-loop relative
errors with a declared controller (``--controller``)."""

from __future__ import annotations

import argparse
import sys
import warnings
from typing import TYPE_CHECKING

from hframe_id.cli.fit_command import resolve_dataset
from hframe_id.cli.outputs import add_force_option, check_dir, output_folder, written_together
from hframe_id.cli.progress import Progress, add_quiet_option
from hframe_id.errors import OptionError

if TYPE_CHECKING:  # the validation package (NumPy, CasADi) is imported when the command runs
    from hframe_id.validation import ValidationOptions

#: The defaults of ``ValidationOptions``, stated in --help without importing the validation
#: (SciPy, CasADi); tests/cli/test_cli_help.py checks that they agree.
HELP_DEFAULTS = {
    "horizon": 10,
    "window": 10,
    "max_lag": 25,
    "init_samples": 20,
    "friction": "sign",
}


def register(subparsers: argparse._SubParsersAction) -> None:
    """Register the ``validate`` subcommand."""
    parser = subparsers.add_parser(
        "validate",
        help="simulation / k-step fit [%%] and residual tests of parameter files on recordings",
        description=(
            "Simulate recordings with a parameter file (and any --params files, side by side) "
            "and report per output channel the simulation fit [%] = 100 (1 - |y - y_hat| / "
            "|y - mean(y)|), the k-step-ahead prediction fit [%], and the simulation "
            "residual's autocorrelation and cross-correlation with each input against the "
            "99 %% band; per parameter file the open-loop RMSE after --init-samples, the "
            "inverse-model force error [%%] and, with --controller, the closed-loop relative "
            "errors [%%] of position, velocity, acceleration and force, as the EMPS benchmark "
            "computes them (docs/validation.md). Exit status: 0 done, 2 bad input."
        ),
    )
    parser.add_argument("fit", metavar="FIT.yaml", help="parameter file to validate")
    parser.add_argument(
        "recordings",
        nargs="+",
        metavar="RECORDING",
        help="MCAP recordings of one rig; a bare name is looked up in ./datasets/, then in "
        "the project's shipped datasets/",
    )
    parser.add_argument(
        "--params",
        action="append",
        default=[],
        metavar="OTHER.yaml",
        help="another parameter file to compare (repeatable), e.g. models/hframe-8-table4.2.yaml",
    )
    parser.add_argument(
        "--horizon",
        type=int,
        metavar="K",
        help=f"prediction horizon [samples] (0: no prediction; default {HELP_DEFAULTS['horizon']})",
    )
    parser.add_argument(
        "--window",
        type=int,
        metavar="M",
        help="past samples for the prediction's state estimate "
        f"(default {HELP_DEFAULTS['window']})",
    )
    parser.add_argument(
        "--max-lag",
        type=int,
        metavar="L",
        help="largest lag of the residual correlations [samples] "
        f"(default {HELP_DEFAULTS['max_lag']})",
    )
    parser.add_argument(
        "--init-samples",
        type=int,
        metavar="N",
        help="samples that initialise the open-loop RMSE, not counted in it "
        f"(default {HELP_DEFAULTS['init_samples']})",
    )
    parser.add_argument(
        "--controller",
        metavar="FILE.py",
        help="the controller the rig ran under (docs/custom-models.md): simulate every "
        "parameter file in closed loop with it, on the recordings' references and "
        "disturbances, e.g. models/emps_controller.py",
    )
    parser.add_argument(
        "--friction",
        metavar="{sign,smooth,stick-slip}",
        help="Coulomb friction law of the closed loop and the inverse model: sign (the "
        "benchmarks' discontinuous law, their published numbers; default), smooth (the "
        "model's tanh, as fitted) or stick-slip (Table 2.2)",
    )
    parser.add_argument(
        "--plot",
        type=output_folder("--plot"),
        metavar="DIR",
        help="write compare and resid PNGs to DIR",
    )
    add_force_option(parser)
    add_quiet_option(parser)
    parser.add_argument("--json", action="store_true", help="print the results as JSON")
    parser.set_defaults(handler=run)


def _read(names: list[str]) -> list:
    from hframe_id.recordings import read_recording

    recordings = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for name in names:
            recordings.append(read_recording(resolve_dataset(name)))
    for warning in caught:
        print(f"hframe-id: warning: {warning.message}", file=sys.stderr)
    return recordings


def _check_lengths(options: ValidationOptions, name: str, samples: int) -> None:
    """The options counted in samples fit in the recording ``name`` of ``samples`` samples:
    the largest lag, the prediction's window and horizon, the open-loop RMSE's start."""
    spans = {
        "--max-lag": options.max_lag,
        "--window + --horizon": options.window + options.horizon if options.horizon else 0,
        "--init-samples": options.init_samples,
    }
    for option, span in spans.items():
        if span >= samples:
            raise OptionError(f"{option} {span}: longer than {name} ({samples} samples)")


def run(args: argparse.Namespace) -> int:
    """Run ``hframe-id validate``: fit [%] and residual tests as text or JSON, plots if asked."""
    from hframe_id.parameters import load_parameter_file
    from hframe_id.validation import ValidationOptions, validate
    from hframe_id.validation.compare import labels_of
    from hframe_id.validation.output import to_document, to_text
    from hframe_id.validation.plots import plot_names, write_plots

    given = {k: getattr(args, k) for k in HELP_DEFAULTS if getattr(args, k) is not None}
    if args.controller is not None:
        from hframe_id.cli.declared_control import check_loop_length
        from hframe_id.control import load_controller_file

        given["controller"] = load_controller_file(args.controller)
    options = ValidationOptions(**given)
    parameter_sets = [load_parameter_file(path) for path in [args.fit, *args.params]]
    recordings = _read(args.recordings)
    for name, recording in zip(args.recordings, recordings, strict=True):
        _check_lengths(options, name, len(recording.time_s))
        if options.controller is not None:
            check_loop_length(options.controller, recording, f"--controller {args.controller}")
    plot_dir = None
    if args.plot is not None:
        names = plot_names([r.name() for r in recordings], labels_of(parameter_sets))
        plot_dir = check_dir(args.plot, "--plot", files=names, force=args.force)
    what = f"validating {len(parameter_sets)} parameter file(s) on {len(recordings)} recording(s)"
    with Progress(args.quiet).slow(what):
        result = validate(parameter_sets, recordings, options)
    written = []
    if plot_dir is not None:
        with written_together() as staging:
            written = write_plots(result.recordings, plot_dir, staging)
    if args.json:
        from hframe_id.cli import json_output

        print(json_output.text(to_document(result)))
    else:
        print(to_text(result))
        if plot_dir is not None:
            print(f"plots: {len(written)} PNG files in {plot_dir}")
    return 0
