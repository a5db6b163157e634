"""``hframe-id batch``: fit every entry of a manifest on a Dask cluster into a results store."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from hframe_id.cli import signals
from hframe_id.cli.numbers import add_number
from hframe_id.cli.outputs import check_dir, check_file, output_folder
from hframe_id.errors import Interrupted, OptionError

if TYPE_CHECKING:  # Dask is imported when a batch runs, not for --help
    from distributed import Client


#: Most LocalCluster workers: 4 per CPU (each is a Python process with CasADi loaded;
#: --workers 100000 tried to start them all).
MAX_WORKERS = 4 * (os.cpu_count() or 1)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``hframe-id batch`` and its options to ``subparsers``."""
    parser = subparsers.add_parser(
        "batch",
        help="fit every entry of a manifest on Dask into Parquet",
        description=(
            "Fit every entry of a manifest (YAML or CSV: rig, time, recordings, model, "
            "initial, free; docs/fleet.md) on a Dask cluster and store one row per fit in a "
            "Parquet file, written as fits finish. Fits already in the store (same recordings' "
            "sha256, model, initial file and options) are skipped. A fit that fails is a row "
            "with its status and message. Parameter files (and reports) go to --out-dir. "
            "Exit status: 0 every fit stored (even failed ones), 2 bad input (an unreachable "
            "--scheduler too), 130 Ctrl-C or SIGTERM (finished rows kept with their files, "
            "none of the unfinished fits' files)."
        ),
    )
    parser.add_argument("manifest", metavar="MANIFEST", help="the manifest (.yaml or .csv)")
    parser.add_argument(
        "--results", required=True, metavar="FILE", help="the results store (.parquet)"
    )
    parser.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="an existing Dask scheduler (tcp://host:8786), used as it is; default: a "
        "LocalCluster on this machine",
    )
    add_number(
        parser,
        "--workers",
        int,
        at_least=1,
        at_most=MAX_WORKERS,
        metavar="N",
        help="LocalCluster worker processes, one thread each (default: the CPU count; "
        f"at most {MAX_WORKERS}, 4 per CPU)",
    )
    parser.add_argument("--force", action="store_true", help="redo fits already stored")
    parser.add_argument(
        "--out-dir",
        type=output_folder("--out-dir"),
        metavar="DIR",
        help="where parameter files and reports go (default: <results stem>-fits/ beside "
        "the results)",
    )
    parser.add_argument(
        "--no-reports",
        action="store_true",
        help="write each fit's parameter file only, not its report with plots (~3 s a fit)",
    )
    parser.add_argument("--quiet", action="store_true", help="no line per fit on stderr")
    parser.set_defaults(handler=run)


@contextmanager
def _client(scheduler: str | None, workers: int | None) -> Iterator[Client]:
    """``dask_client``, started with Ctrl-C and SIGTERM deferred (``signals.deferred``): a
    LocalCluster interrupted while it starts cannot be closed, and Dask's exit handler then
    prints a traceback. The interrupt ends the batch as soon as the cluster is up (seconds),
    closing it."""
    from hframe_id.fleet.runner import dask_client

    with ExitStack() as stack:
        with signals.deferred():
            client = stack.enter_context(dask_client(scheduler, workers))
        yield client


def run(args: argparse.Namespace) -> int:
    """Run ``hframe-id batch``: fit the manifest's pending entries on Dask into the results
    store; exit status 0 when every fit was stored (failed fits are rows too)."""
    from hframe_id.fleet.manifest import load_manifest
    from hframe_id.fleet.runner import run_batch
    from hframe_id.fleet.store import ResultsStore

    if args.scheduler and args.workers is not None:
        raise OptionError("--workers starts a LocalCluster; it cannot go with --scheduler")
    results = Path(args.results)
    if results.suffix != ".parquet":
        raise OptionError(f"--results {results}: expected a .parquet file")
    # The store grows run after run, so an existing one is no error (force=True); --force
    # here means redoing stored fits.
    check_file(results, "--results", force=True, make_parents=True)
    out_dir = Path(args.out_dir) if args.out_dir else results.with_name(f"{results.stem}-fits")
    check_dir(out_dir, "--out-dir")
    jobs = load_manifest(args.manifest)
    store = ResultsStore(results)

    def progress(row: dict, done: int, total: int) -> None:
        if not args.quiet:
            print(
                f"[{done}/{total}] {row['rig']} {row['run_time'].isoformat()}: "
                f"{row['status']} ({row['wall_time [s]']:.1f} s) {row['message']}",
                file=sys.stderr,
                flush=True,
            )

    try:
        summary = run_batch(
            jobs,
            store,
            lambda: _client(args.scheduler, args.workers),
            out_dir,
            force=args.force,
            reports=not args.no_reports,
            progress=progress,
        )
    except KeyboardInterrupt as err:
        raise Interrupted(f"{str(err) or 'Ctrl-C'}; {len(store)} row(s) in {results}") from None
    print(f"{summary.line()}; {len(store)} row(s) in {results}")
    return 0
