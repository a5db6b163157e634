"""``hframe-id datasets``: make (``make datasets``), list and verify the shipped recordings."""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from functools import partial
from pathlib import Path

from hframe_id.cli import signals
from hframe_id.cli.json_output import emit
from hframe_id.cli.outputs import check_dir, output_folder, written_together
from hframe_id.errors import LogFormatError, renamed


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
        "--out",
        type=output_folder("--out"),
        help="folder (datasets; with --realistic datasets/realistic)",
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


@contextmanager
def _scratch(out: Path) -> Iterator[Path]:
    """A hidden temporary folder in ``out``'s nearest existing folder (the same file system,
    so that its files can be renamed into place), removed with its contents afterwards,
    and by the signal watchdog (``signals.discard_on_exit``)."""
    parent = next(folder for folder in (out, *out.parents) if folder.is_dir())
    scratch = Path(tempfile.mkdtemp(prefix=".hframe-id-datasets.", dir=parent))
    remove = partial(shutil.rmtree, scratch, ignore_errors=True)
    try:
        with signals.discard_on_exit(remove):
            yield scratch
    finally:
        remove()


def run_make(args: argparse.Namespace) -> int:
    """Run ``hframe-id datasets make``: write truth files, recordings and manifest.

    Everything is made in a scratch folder, then put in place together: Ctrl-C, SIGTERM or
    a failure leaves ``--out`` as it was (with ``--only``, the manifest's other entries are
    kept: the old manifest is the scratch folder's start).
    """
    from hframe_id.rig.datasets import MANIFEST, make_datasets

    def report(spec, summary) -> None:
        signals.check()  # an interrupt swallowed while recording (numpy, CasADi): ends here
        print(f"{spec.file:<20} {summary.samples} samples, truth {spec.truth}, seed {spec.seed}")

    out = check_dir(
        args.out
        if args.out is not None
        else ("datasets/realistic" if args.realistic else "datasets"),
        "--out",
    )
    with written_together() as staging, _scratch(out) as scratch:
        if args.only and (out / MANIFEST).is_file():
            shutil.copyfile(out / MANIFEST, scratch / MANIFEST)
        try:
            made = make_datasets(scratch, args.only, progress=report, collection=_collection(args))
        except LogFormatError as err:  # a full disk, say: name --out, not the scratch folder
            raise renamed(err, scratch, out) from None
        for path in sorted(p for p in scratch.rglob("*") if p.is_file()):
            os.replace(path, staging.file(out / path.relative_to(scratch)))
    print(f"manifest             {out / made.relative_to(scratch)}")
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
