"""``hframe-id import FILE --map ... --out run.mcap``: CSV and MATLAB logs into the log format."""

from __future__ import annotations

import argparse
import datetime as dt
import sys

from hframe_id.cli.outputs import add_force_option, check_file, check_input, output_file
from hframe_id.cli.progress import Progress, add_quiet_option
from hframe_id.errors import OptionError
from hframe_id.recordings.import_spec import ROLES, ColumnMap, ImportSpec
from hframe_id.recordings.units import KNOWN_UNITS

EPILOG = """\
examples:
  hframe-id import run.csv --map t=time:ms --map u=input:V --map pos=output:mm:x \\
      --noise-std x=0.002:mm --variant my-axis --out run.mcap
  hframe-id import DATA_EMPS.mat --map t=time:s --map vir=input:V --map qm=output:m \\
      --map qg=signal:m --variant emps-axis --noise-std qm=estimate --out emps.mcap
  hframe-id import servo.mat --map 'data(:,1)=time:s' --map 'data(:,2)=input:V:u' \
      --map 'data(:,4)=output:rad/s:w' --variant my-rotor --out servo.mcap

Every value is converted to SI at import (mm -> m, deg -> rad, counts -> rad with
--counts-per-rev, ms -> s). The numeric 1x1 variables of a .mat file (gains, constants) are
stored as rig metadata under their own names. A failed import writes nothing. See
docs/import.md.
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    """Register the ``import`` subcommand."""
    parser = subparsers.add_parser(
        "import",
        help="convert a CSV or MATLAB .mat log into the log format (any rig)",
        description="Convert a CSV or MATLAB .mat (v4 to v7) log of any rig into an hframe-id\n"
        "recording (log format 1.1, hframe_id.SignalSample): which column is which input,\n"
        "output or extra signal and its unit, the sample time, the sensors' noise levels,\n"
        "rig and experiment metadata. Exit status 2, and no output file, for bad input.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("file", metavar="FILE", help="the log: .csv (.tsv, .txt) or .mat")
    parser.add_argument(
        "--map",
        action="append",
        required=True,
        metavar="SOURCE=ROLE:UNIT[:NAME]",
        help=f"column (CSV) or variable (.mat) SOURCE is one of {', '.join(ROLES)} (signal: "
        "recorded, not a model input or output) in UNIT, named NAME in the recording (default "
        "SOURCE); repeat for each column. A column of a .mat matrix is 'data(:,3)' (MATLAB, "
        "1-based) or 'data[:,2]' (NumPy, 0-based; the same column) and needs a NAME. Units: "
        f"{', '.join(KNOWN_UNITS)}",
    )
    parser.add_argument(
        "--out",
        type=output_file("--out", ".mcap"),
        required=True,
        metavar="PATH",
        help="the recording (.mcap)",
    )
    add_force_option(parser)
    add_quiet_option(parser)
    parser.add_argument(
        "--variant", required=True, help="model variant of the rig (letters, digits, '-', '_')"
    )
    parser.add_argument(
        "--sample-period",
        type=float,
        metavar="SECONDS",
        help="nominal sample period [s]; without a time column, sample k is at k * SECONDS "
        "(default with one: the median time step)",
    )
    parser.add_argument(
        "--counts-per-rev", type=float, metavar="N", help="encoder resolution for unit counts"
    )
    parser.add_argument(
        "--noise-std",
        action="append",
        default=[],
        metavar="OUTPUT=VALUE[:UNIT]",
        help="sensor noise std of an output (in its SI unit unless UNIT is given), or "
        "OUTPUT=estimate to have the fitter estimate it; repeat per output",
    )
    parser.add_argument(
        "--nan-invalid",
        action="append",
        default=[],
        metavar="OUTPUT",
        help="mark the output's missing values (empty, NaN) invalid instead of failing "
        "(never for inputs)",
    )
    parser.add_argument("--rig-name", default="", help="the rig's name (rig.name)")
    parser.add_argument(
        "--rig",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="more rig metadata, SI units in the key (e.g. screw_lead_m=0.0025)",
    )
    parser.add_argument(
        "--experiment",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="more experiment metadata",
    )
    parser.add_argument("--description", default="", help="what the experiment was")
    parser.add_argument("--citation", default="", help="where the data come from (reference)")
    parser.add_argument("--operator", default="unknown", help="who ran the experiment")
    parser.add_argument(
        "--protocol",
        default="external",
        help="kind of experiment (default: external, run outside hframe-id)",
    )
    parser.add_argument(
        "--start-time",
        metavar="ISO",
        help="when sample 0 was taken, ISO 8601 with time zone (default: unknown)",
    )
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    """Run ``hframe-id import``: convert the file with the ``--map`` columns into ``--out``."""
    from hframe_id.recordings.importer import import_recording

    check_input(args.file)
    try:
        spec = ImportSpec(
            columns=tuple(ColumnMap.parse(text) for text in args.map),
            variant=args.variant,
            sample_period_s=args.sample_period,
            counts_per_rev=args.counts_per_rev,
            noise_std=_pairs("--noise-std", args.noise_std),
            nan_invalid=tuple(args.nan_invalid),
            rig_name=args.rig_name,
            rig=_pairs("--rig", args.rig),
            experiment=_pairs("--experiment", args.experiment),
            description=args.description,
            citation=args.citation,
            operator=args.operator,
            protocol=args.protocol,
            start_time=_start_time(args.start_time),
        )
    except OptionError as err:
        raise OptionError(f"{args.file}: {err}") from None
    check_file(args.out, "--out", args.force, make_parents=True)
    with Progress(args.quiet).slow(f"importing {args.file}"):  # a long log: tens of seconds
        result = import_recording(args.file, args.out, spec, overwrite=args.force)
    channels = result.channels
    print(
        f"wrote {result.path}: {result.n_samples} samples at {result.sample_period_s * 1e3:g} "
        f"ms ({result.duration_s:.3f} s)",
        file=sys.stderr,
    )
    for kind, names, units in (
        ("inputs", channels.inputs, channels.input_units),
        ("outputs", channels.outputs, channels.output_units),
        ("signals", channels.signals, channels.signal_units),
    ):
        if names:
            listed = ", ".join(f"{n} [{u}]" for n, u in zip(names, units, strict=True))
            print(f"  {kind:<8} {listed}", file=sys.stderr)
    if result.scalars:
        print(f"  rig metadata from the file: {', '.join(result.scalars)}", file=sys.stderr)
    return 0


def _pairs(option: str, items: list[str]) -> dict[str, str]:
    pairs = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise OptionError(f"{option} {item!r}: expected KEY=VALUE")
        if key.strip() in pairs:
            raise OptionError(f"{option}: {key.strip()} given twice")
        pairs[key.strip()] = value.strip()
    return pairs


def _start_time(text: str | None) -> dt.datetime | None:
    if text is None:
        return None
    try:
        return dt.datetime.fromisoformat(text)
    except ValueError:
        raise OptionError(f"--start-time {text!r}: not an ISO 8601 time") from None
