"""``hframe-id datasets``: make (``make datasets``), list and verify the shipped recordings."""

from __future__ import annotations

import argparse
from pathlib import Path

from hframe_id.cli.json_output import emit
from hframe_id.cli.outputs import check_dir
from hframe_id.errors import LogFormatError


def register(subparsers: argparse._SubParsersAction) -> None:
    """Register the ``datasets`` subcommand (``make``, ``list``, ``verify``)."""
    parser = subparsers.add_parser(
        "datasets",
        help="make, list or verify the shipped datasets",
        description="The thesis's open-loop experiments recorded from the sim rig with "
        "documented truth parameters and seeds (see hframe_id/rig/datasets.py); with "
        "--realistic, from the realistic plants (docs/realistic-rig.md).",
    )
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    make = actions.add_parser("make", help="(re)generate truth files, recordings, manifest")
    make.add_argument(
        "--out", type=Path, help="folder (datasets; with --realistic datasets/realistic)"
    )
    make.add_argument(
        "--realistic", action="store_true", help="the realistic-plant datasets instead"
    )
    make.add_argument(
        "--only",
        nargs="+",
        default=(),
        metavar="FILE",
        help="make only these recordings (e.g. 4V_xmotion.mcap)",
    )
    make.set_defaults(handler=run_make)
    listing = actions.add_parser("list", help="list the datasets and what they are")
    listing.add_argument("--realistic", action="store_true", help="the realistic-plant datasets")
    listing.add_argument("--json", action="store_true", help="print one JSON object")
    listing.set_defaults(handler=run_list)
    verify = actions.add_parser("verify", help="check files against the manifest's sha256")
    verify.add_argument("--dir", type=Path, default=Path("datasets"), help="folder (datasets)")
    verify.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object (exit status 2 still when a file does not match)",
    )
    verify.set_defaults(handler=run_verify)


def _collection(args: argparse.Namespace):
    from hframe_id.rig.datasets import REALISTIC, STANDARD

    return REALISTIC if args.realistic else STANDARD


def run_make(args: argparse.Namespace) -> int:
    """Run ``hframe-id datasets make``: write truth files, recordings and manifest."""
    from hframe_id.rig.datasets import make_datasets

    def report(spec, summary) -> None:
        print(f"{spec.file:<20} {summary.samples} samples, truth {spec.truth}, seed {spec.seed}")

    out = check_dir(args.out or ("datasets/realistic" if args.realistic else "datasets"), "--out")
    manifest = make_datasets(out, args.only, progress=report, collection=_collection(args))
    print(f"manifest             {manifest}")
    return 0


def run_list(args: argparse.Namespace) -> int:
    """Run ``hframe-id datasets list``: each recording with its truth file, seed and description."""
    collection = _collection(args)
    rows = [
        {
            "file": spec.file,
            "truth": collection.truths[spec.truth].file,
            "seed": spec.seed,
            "description": spec.description,
        }
        for spec in collection.datasets
    ]
    if args.json:
        emit("datasets list", {"realistic": args.realistic, "datasets": rows})
        return 0
    for row in rows:
        print(f"{row['file']:<20} {row['truth']:<30} seed {row['seed']:<5} {row['description']}")
    return 0


def run_verify(args: argparse.Namespace) -> int:
    """Run ``hframe-id datasets verify`` against the manifest's SHA-256 sums.

    Exit status 0 if every file matches; on a mismatch 2 with ``--json``, else LogFormatError.
    """
    from hframe_id.rig.datasets import verify_datasets

    problems = verify_datasets(args.dir)
    if args.json:
        emit("datasets verify", {"dir": args.dir, "ok": not problems, "problems": problems})
        return 2 if problems else 0
    if problems:
        raise LogFormatError("; ".join(problems))
    print(f"{args.dir}: every file matches the manifest")
    return 0
