"""``hframe-id fleet make`` (a synthetic fleet from the sim rig) and ``hframe-id fleet report``
(rig histories and drift flags from a batch's results)."""

from __future__ import annotations

import argparse
from pathlib import Path

from hframe_id.cli import signals
from hframe_id.cli.numbers import add_number
from hframe_id.cli.outputs import add_force_option, check_dir, output_folder, written_together
from hframe_id.cli.progress import Progress, add_quiet_option
from hframe_id.errors import OptionError

#: What ``fleet report`` writes into its folder: the page, and the plots (replaced as a whole).
REPORT_PAGE = "fleet-report.md"
REPORT_PLOTS = "plots"


#: Most weekly runs (rigs x weeks) one ``fleet make`` records: 10 000 runs are 30 000
#: recordings, hours of work and about 2.7 GB; 100 000 x 100 000 started as if feasible.
MAX_RUNS = 10_000


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``hframe-id fleet make`` and ``hframe-id fleet report`` to ``subparsers``."""
    parser = subparsers.add_parser(
        "fleet",
        help="synthetic fleets; rig histories and drift flags",
        description="Rig histories over time: 'make' records a synthetic fleet with the sim "
        "rig, 'report' plots each parameter per rig and flags drift (docs/fleet.md).",
    )
    actions = parser.add_subparsers(dest="fleet_action", metavar="ACTION", required=True)
    make = actions.add_parser(
        "make",
        help="record a synthetic fleet: DIR/manifest.yaml, DIR/aging.yaml, recordings",
        description="Record N rigs x W weekly runs (three 1 s steps each) with the sim rig: "
        "rigs spread +/-10 %% around Table 4.2, 1 %% week-to-week scatter, and half the rigs "
        "aged (belt stiffness, friction, motor 2 gain, a mild belt below 10 %%). Writes "
        "DIR/manifest.yaml for 'hframe-id batch' and DIR/aging.yaml (what was aged, by "
        "how much). The same seed gives the same fleet.",
    )
    add_number(make, "--rigs", int, at_least=1, required=True, metavar="N", help="number of rigs")
    add_number(
        make, "--weeks", int, at_least=2, required=True, metavar="W", help="weekly runs (>= 2)"
    )
    add_number(make, "--seed", int, at_least=0, default=0, metavar="S", help="random seed")
    make.add_argument(
        "--out",
        type=output_folder("--out"),
        required=True,
        metavar="DIR",
        help="new (or empty) folder",
    )
    make.add_argument(
        "--plant",
        choices=("sim", "realistic"),
        default="sim",
        help="sim: plants of the fitted model (default); realistic: hframe-20 plants with "
        "stick-slip friction, current limit and delays (docs/realistic-rig.md)",
    )
    add_quiet_option(make)
    make.set_defaults(handler=run_make)
    report = actions.add_parser(
        "report",
        help="plot each parameter over time per rig and flag drift",
        description="Per rig and parameter, the change of the latest successful fit against "
        "the first; flagged when it is at least --threshold, the 95 %% interval of the "
        "difference excludes zero, and it stands out at 95 %% against the week-to-week "
        "scatter of the other rigs' estimates. Prints the flags table (or --json), writes "
        "one plot per parameter and a markdown page. Exit status 0 (also with flags), 2 bad input.",
    )
    report.add_argument("results", metavar="RESULTS", help="a results store (.parquet)")
    add_number(
        report,
        "--threshold",
        above=0,
        below=1,
        default=None,
        metavar="FRACTION",
        help="relative change that counts as drift (default 0.1)",
    )
    report.add_argument(
        "--out",
        type=output_folder("--out"),
        metavar="DIR",
        help="plots and fleet-report.md go here (default: <results stem>-report/)",
    )
    add_force_option(report)
    report.add_argument(
        "--json",
        action="store_true",
        help='print one JSON object (counts, threshold, "flagged": [{"rig", "parameter", '
        '"change", ...}])',
    )
    report.set_defaults(handler=run_report)


def run_make(args: argparse.Namespace) -> int:
    """Run ``hframe-id fleet make``: record the synthetic fleet and write its manifest and
    ``aging.yaml``."""
    from hframe_id.fleet.synthetic import make_fleet

    progress = Progress(args.quiet)

    def recorded(rig: str, week: int) -> None:
        signals.check()  # an interrupt swallowed while recording (numpy, CasADi): ends here
        progress.line(f"{rig} week {week}: recorded")

    runs = args.rigs * args.weeks
    if runs > MAX_RUNS:
        raise OptionError(
            f"--rigs {args.rigs} x --weeks {args.weeks} is {runs:,} weekly runs; at most "
            f"{MAX_RUNS:,} (each is three recordings, about 1 s)"
        )
    out = check_dir(args.out, "--out", empty=True)
    with written_together() as staging:
        folder = staging.folder(out)
        manifest = make_fleet(
            args.rigs,
            args.weeks,
            args.seed,
            folder,
            recorded,
            args.plant,
        )
    print(f"manifest: {out / manifest.name}")
    print(f"aging: {out / 'aging.yaml'}")
    return 0


def run_report(args: argparse.Namespace) -> int:
    """Run ``hframe-id fleet report``: each rig's parameter history, the drift flags as a
    table or ``--json``, plots and ``fleet-report.md``."""
    from hframe_id.fleet.drift import DEFAULT_THRESHOLD, drift_table
    from hframe_id.fleet.report import (
        flags_table,
        format_table,
        plot_histories,
        structure_lines,
        summary,
        write_markdown,
    )
    from hframe_id.fleet.store import read_results

    threshold = DEFAULT_THRESHOLD if args.threshold is None else args.threshold
    results = Path(args.results)
    if not results.is_file():
        raise OptionError(f"{results}: no such results file")
    out = args.out if args.out is not None else results.with_name(f"{results.stem}-report")
    check_dir(out, "--out", files=(REPORT_PAGE,), folders=(REPORT_PLOTS,), force=args.force)
    frame = read_results(results)
    if frame.empty:
        raise OptionError(f"{results}: holds no fits; nothing to report")
    drifts = drift_table(frame, threshold)
    report = summary(frame, drifts, threshold, results, out / REPORT_PLOTS)
    with written_together() as staging:
        plots = plot_histories(frame, threshold, out / REPORT_PLOTS, staging)
        page = write_markdown(report, drifts, plots, out / REPORT_PAGE, staging)
    if args.json:
        from hframe_id.cli import json_output

        print(json_output.text(report))
        return 0
    by_status = ", ".join(f"{n} {s}" for s, n in report["by_status"].items())
    print(f"{report['fits']} fits of {report['rigs']} rigs ({by_status})")
    rows = flags_table(drifts)
    if len(rows) > 1:
        print(
            f"drift >= {100 * threshold:g} % (95 % interval excludes no change; beyond the "
            "other rigs' week-to-week scatter at 95 %):"
        )
        print(format_table(rows))
    else:
        print(f"no drift >= {100 * threshold:g} %")
    for line in structure_lines(report["structure_changes"]):
        print(line)
    print(f"report: {page} ({len(plots)} plots)")
    return 0
