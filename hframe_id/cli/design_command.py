"""``hframe-id design``: which experiment to record, within the rig's voltage and travel.

Writes the design as a CSV voltage sequence (``hframe-id record --protocol csv`` plays it),
a markdown report next to it (``design.md`` for ``design.csv``: the predicted standard
errors beside the thesis's six steps, a PRBS and a multisine) and its plot (``design.png``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from hframe_id.cli.numbers import add_number
from hframe_id.cli.outputs import (
    add_force_option,
    check_distinct,
    check_file,
    check_length,
    output_file,
    written_together,
)
from hframe_id.cli.progress import Progress, add_quiet_option
from hframe_id.errors import OptionError, shown

#: Most parameter sets drawn: a 4 s design with 2 draws takes about 14 s (docs/design.md),
#: so 100 is the better part of an hour; 100 000 ran for days.
MAX_DRAWS = 100


def register(subparsers: argparse._SubParsersAction) -> None:
    """Register the ``design`` subcommand."""
    parser = subparsers.add_parser(
        "design",
        help="design an experiment within the rig's limits",
        description="Choose the motors' voltages for an experiment of a given duration so "
        "that a fit of its recording determines the free parameters best (D-optimal by "
        "default), predicted with the fitter's own transcription at the parameter file's "
        "values and at parameter sets drawn around them, keeping the predicted motion inside "
        "the travel with a margin (docs/design.md).",
    )
    parser.add_argument(
        "--params", required=True, metavar="FILE", help="parameter file (a table or a fit)"
    )
    add_number(parser, "--duration", above=0, required=True, help="record duration [s]")
    add_number(
        parser, "--max-voltage", above=0, required=True, help="voltage limit of each motor [V]"
    )
    parser.add_argument(
        "--travel",
        action="append",
        required=True,
        metavar="AXIS=LOW:HIGH",
        help="travel of an axis from where the record starts [m], e.g. x=-0.2:0.2; give x and y",
    )
    add_number(
        parser,
        "--margin",
        at_least=0,
        default=None,
        help="distance kept from each travel limit on the model [m] (default 0.05)",
    )
    parser.add_argument("--criterion", choices=("D", "A", "E"), default="D")
    parser.add_argument(
        "--focus",
        metavar="NAMES",
        help="comma-separated free parameters to determine best (overrides --criterion)",
    )
    parser.add_argument(
        "--free", metavar="NAMES", help="comma-separated free parameters (default: the fit's)"
    )
    parser.add_argument(
        "--after",
        nargs="+",
        type=Path,
        default=[],
        metavar="REC",
        help="recordings (MCAP) already made of this rig: their information is added, so the "
        "design brings what they lack (a sequential design)",
    )
    parser.add_argument(
        "--calibrate",
        nargs="+",
        type=Path,
        default=[],
        metavar="REC",
        help="the recordings the --params fit was made from: its reported errors over those "
        "predicted for them (model error) scale every prediction",
    )
    add_number(
        parser,
        "--draws",
        int,
        at_least=0,
        at_most=MAX_DRAWS,
        default=2,
        help=f"parameter sets drawn (default 2, at most {MAX_DRAWS}; each costs about a "
        "prediction at the file's values)",
    )
    add_number(parser, "--seed", int, at_least=0, default=0, help="seed of the draws (0)")
    parser.add_argument(
        "--out", type=output_file("--out"), required=True, help="design to write (.csv)"
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    add_force_option(parser)
    add_quiet_option(parser)
    parser.set_defaults(handler=run)


def parse_travel(values: list[str]) -> dict[str, tuple[float, float]]:
    """``["x=-0.2:0.2", ...]`` -> ``{"x": (-0.2, 0.2)}``; ``OptionError`` naming the value."""
    import math

    travel: dict[str, tuple[float, float]] = {}
    for text in values:
        axis, _, span = text.partition("=")
        low, _, high = span.partition(":")
        try:
            bounds = (float(low), float(high))
        except ValueError:
            bounds = (math.nan, math.nan)
        if axis not in ("x", "y") or not all(math.isfinite(b) for b in bounds):
            raise OptionError(
                f"--travel {shown(text)}: expected AXIS=LOW:HIGH [m] with AXIS x or y, e.g. "
                "x=-0.2:0.2"
            )
        if not bounds[0] < bounds[1]:
            raise OptionError(f"--travel {shown(text)}: LOW must be below HIGH")
        if axis in travel:
            raise OptionError(f"--travel {axis} given twice")
        travel[axis] = bounds
    return travel


def _names(text: str | None, option: str) -> tuple[str, ...]:
    """The comma-separated names given with ``option`` (none if it was not given); given but
    naming none (``--free ''``) is an error, not the default set."""
    if text is None:
        return ()
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if not names:
        raise OptionError(f"{option} {shown(text)}: names no parameter")
    return names


def run(args: argparse.Namespace) -> int:
    """Run ``hframe-id design``: the design, its report and plot, written together."""
    out = Path(args.out)
    report_path, plot_path = out.with_suffix(".md"), out.with_suffix(".png")
    if out.suffix.lower() != ".csv":
        raise OptionError(f"--out {out}: the design is a CSV voltage sequence; name it .csv")
    for path in (out, report_path, plot_path):
        check_file(path, "--out", args.force)
    travel = parse_travel(args.travel)
    from hframe_id.design.criteria import Criterion
    from hframe_id.design.optimise import TRAVEL_MARGIN_M, DesignOptions, Limits
    from hframe_id.parameters import load_parameter_file
    from hframe_id.recordings.sensors import SensorModel
    from hframe_id.simulation.integrators import check_simulable

    options = DesignOptions(
        criterion=Criterion(args.criterion, _names(args.focus, "--focus")),
        free=_names(args.free, "--free") or None,
        draws=args.draws,
        seed=args.seed,
        prior_tables=_recorded_inputs(args.after, "--after"),
    )
    calibration = _recorded_inputs(args.calibrate, "--calibrate")
    limits = Limits(
        args.max_voltage, travel, TRAVEL_MARGIN_M if args.margin is None else args.margin
    )
    limits.check(SensorModel())
    check_length(args.duration, options.sample_period_s, "--duration")
    params = load_parameter_file(args.params)
    _check_model(params, args.params)
    check_simulable(params, options.sample_period_s, f"--params {args.params}")
    return _design(args, params, limits, options, calibration, (out, report_path, plot_path))


def _recorded_inputs(paths: list[Path], option: str) -> tuple:
    """The commanded voltages (N, 2) [V] of the recordings ``paths`` (given with ``option``)."""
    import math

    from hframe_id.recordings.reader import read_recording

    check_distinct(paths, option)
    tables = []
    for path in paths:
        recording = read_recording(path)
        if tuple(recording.input_names) != ("u1", "u2"):
            raise OptionError(
                f"{option} {path}: inputs {', '.join(recording.input_names)}, not an H-frame's "
                "u1, u2"
            )
        if not math.isclose(recording.sample_period_s, 1e-3, rel_tol=1e-9):
            raise OptionError(
                f"{option} {path}: sample period {recording.sample_period_s:g} s; the design's "
                "is 0.001 s"
            )
        tables.append(recording.inputs)
    return tuple(tables)


def _check_model(params, path: str) -> None:
    """A design drives two motors and watches x and y: an H-frame model."""
    from hframe_id.models import build_model

    model = build_model(params.variant)
    inputs = tuple(s.name for s in model.inputs)
    outputs = {s.name for s in model.outputs}
    if inputs != ("u1", "u2") or not {"x", "y"} <= outputs:
        raise OptionError(
            f"--params {path}: model {params.variant} has inputs {', '.join(inputs)} and "
            f"outputs {', '.join(sorted(outputs))}; a design needs an H-frame model (u1, u2; x, y)"
        )


def _design(args, params, limits, options, calibration: tuple, paths: tuple) -> int:
    from hframe_id.design.calibration import misfit_factor
    from hframe_id.design.excitation import sequence_text
    from hframe_id.design.optimise import design_experiment, free_parameters
    from hframe_id.design.report import markdown, plot, predictions, summary
    from hframe_id.errors import FitError

    try:
        free_parameters(params, options.free)
        with Progress(args.quiet).slow(f"designing {args.duration:g} s of {params.variant}"):
            design = design_experiment(params, args.duration, limits, options)
            factor = 1.0
            if calibration:
                factor = misfit_factor(
                    params,
                    calibration,
                    design.fit_options,
                    options.sensors,
                    options.sample_period_s,
                )
            rows = predictions(design, params, limits, options, factor)
    except FitError as err:
        raise OptionError(f"--params {args.params}: {err}") from None
    except FloatingPointError as err:
        raise OptionError(
            f"--params {args.params}: the model cannot be simulated at these values or the "
            f"sets drawn around them ({err})"
        ) from None
    out, report_path, plot_path = paths
    dt = options.sample_period_s
    text = markdown(design, rows, params, limits, out.name, plot_path.name, dt, factor)
    with written_together() as staging:
        staging.write(out, sequence_text(design.table, dt))
        staging.write(report_path, text)
        plot(design, limits, dt, options.sensors, staging.file(plot_path))
    if args.json:
        from hframe_id.cli.json_output import emit

        emit(
            "design",
            {
                "csv": out,
                "report": report_path,
                "plot": plot_path,
                **summary(design, rows, limits, factor),
            },
        )
    else:
        lines = [f"wrote {out}, {report_path.name}, {plot_path.name} ({design.wall_time_s:.1f} s)"]
        lines += [
            f"  {r.label:<20} median relative std {100 * r.median_relative_std:.3g} %" for r in rows
        ]
        print("\n".join(lines))
    return 0
