"""``hframe-id export FILE --format F``: parameters and linear models for other tools."""

from __future__ import annotations

import argparse
import sys

from hframe_id.cli.outputs import add_force_option, check_file
from hframe_id.errors import OptionError


def register(subparsers: argparse._SubParsersAction) -> None:
    """Register the ``export`` subcommand."""
    from hframe_id.analysis.formats import FORMATS

    formats = "; ".join(f"{f.name}: {f.description}" for f in FORMATS.values())
    parser = subparsers.add_parser(
        "export",
        help="export parameters or the linear state-space model (JSON, CSV, MATLAB, ...)",
        description="Export a parameter file's values, or its model linearized about rest "
        "(Coulomb friction excluded), for other tools. SI units throughout; names carry "
        f"units. Formats: {formats}.",
    )
    parser.add_argument("file", metavar="FILE", help="parameter file (YAML); names the model")
    parser.add_argument(
        "--format", required=True, metavar="FORMAT", help=f"one of {', '.join(FORMATS)}"
    )
    parser.add_argument(
        "--out", metavar="PATH", help="write here (default: standard output; needed for matlab)"
    )
    add_force_option(parser)
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    """Run ``hframe-id export``: the file in ``--format`` to ``--out`` or standard output."""
    from hframe_id.analysis.export import export_format, render, write_atomic
    from hframe_id.parameters import load_parameter_file

    fmt = export_format(args.format)
    if fmt.binary and args.out is None:
        raise OptionError(f"format {fmt.name} writes a binary {fmt.suffix} file: give --out PATH")
    if args.out is not None:
        check_file(args.out, "--out", args.force)
    data = render(load_parameter_file(args.file), fmt)
    if args.out is not None:
        path = write_atomic(args.out, data, overwrite=args.force)
        print(f"wrote {path} ({fmt.name})", file=sys.stderr)
    else:
        sys.stdout.write(data)
    return 0
