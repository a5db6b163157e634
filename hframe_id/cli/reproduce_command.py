"""``hframe-id reproduce``: the Chapter 5 controller comparison against this simulator.

Runs the four simulated gain sets of Tables 5.1, 5.3, 5.4 and 5.5 on the 1 in test square and
writes a markdown report with plots (``make reproduce``: ``reports/reproduction/report.md``).
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from hframe_id.cli.outputs import add_force_option, check_dir, output_folder, written_together
from hframe_id.cli.progress import Progress, add_quiet_option

#: The shipped parameter file reproduced by default (found wherever the command runs: a
#: path relative to the working directory failed outside the checkout).
DEFAULT_PARAMS = "hframe-8-table4.2.yaml"


def register(subparsers: argparse._SubParsersAction) -> None:
    """Register the ``reproduce`` subcommand (the Chapter 5 controller tables)."""
    parser = subparsers.add_parser(
        "reproduce",
        help="reproduce the Chapter 5 controller tables (markdown report with plots)",
        description="Simulate the four gain sets of sections 5.4-5.5 on the 1 in square and "
        "compare with Tables 5.1, 5.3, 5.4, 5.5 and 5.6 (report.md and plots/ in --out).",
    )
    parser.add_argument(
        "--out", type=output_folder("--out"), required=True, help="report directory"
    )
    add_force_option(parser)
    parser.add_argument(
        "--params",
        type=Path,
        help=f"H-frame parameter file (default: the shipped models/{DEFAULT_PARAMS}, "
        "Table 4.1 + 4.2)",
    )
    parser.add_argument(
        "--no-sensitivity", action="store_true", help="skip the plant-variation table"
    )
    add_quiet_option(parser)
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    """Run ``hframe-id reproduce``: write the report and print each gain set against the thesis."""
    from hframe_id.control.closed_loop import check_hframe
    from hframe_id.control.reproduction import report_files, reproduce, write_report
    from hframe_id.models import build_model
    from hframe_id.parameters import load_parameter_file
    from hframe_id.resources import model_file

    params = load_parameter_file(args.params or model_file(DEFAULT_PARAMS))
    check_hframe(build_model(params.variant))
    check_dir(args.out, "--out", files=report_files(), force=args.force)
    command = "hframe-id " + shlex.join(sys.argv[1:]) if sys.argv[1:2] == ["reproduce"] else ""
    with Progress(args.quiet).slow("reproducing the Chapter 5 tables"):
        rep = reproduce(params, sensitivity=not args.no_sensitivity)
        with written_together() as staging:
            report = write_report(rep, args.out, staging, command)
    ok = rep.within_tolerance()
    print(f"wrote {report}")
    for label, flag in ok.items():
        row = next(r for r in rep.rows if r.thesis.label == label)
        print(
            f"  {label:16s} leg-1 {100 * row.overshoot_deviation(1):+5.0f} %, leg-3 "
            f"{100 * row.overshoot_deviation(3):+5.0f} % vs thesis "
            f"({'within' if flag else 'outside'} 30 %)"
        )
    same = rep.ranking() == rep.thesis_ranking()
    print(f"  ranking {' < '.join(rep.ranking())} ({'same as' if same else 'differs from'} "
          "Table 5.6)")  # fmt: skip
    return 0
