"""``hframe-id reduce FILE --out FILE``: hframe-20 parameters -> hframe-8 parameters (sec. 4.1)."""

from __future__ import annotations

import argparse

from hframe_id.cli.outputs import add_force_option, check_file


def register(subparsers: argparse._SubParsersAction) -> None:
    """Register the ``reduce`` subcommand (hframe-20 to hframe-8, section 4.1)."""
    parser = subparsers.add_parser(
        "reduce",
        help="reduce an hframe-20 parameter file to an hframe-8 one (section 4.1)",
        description="Reduce the 20th-order parameters to the 8th-order model: series belt "
        "springs (eq. 4.6-4.8), idler inertia and friction lumped into the motor pulleys and "
        "the cart (eq. 4.2-4.5).",
    )
    parser.add_argument("file", metavar="FILE", help="hframe-20 parameter file (YAML)")
    parser.add_argument("--out", required=True, metavar="FILE", help="hframe-8 file to write")
    add_force_option(parser)
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    """Run ``hframe-id reduce``: write the reduced hframe-8 parameter file to ``--out``."""
    from hframe_id.parameters import load_parameter_file, save_parameter_file
    from hframe_id.parameters.reduce import reduce_to_hframe8

    check_file(args.out, "--out", args.force, make_parents=True)
    reduced = reduce_to_hframe8(load_parameter_file(args.file))
    path = save_parameter_file(reduced, args.out, overwrite=args.force)
    print(f"wrote {path} ({reduced.variant}, reduced from {args.file})")
    return 0
