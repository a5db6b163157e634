"""``hframe-id params show|check FILE``: print a parameter file as a table, or validate it."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from hframe_id.cli.json_output import emit
from hframe_id.errors import HframeIdError

if TYPE_CHECKING:
    from hframe_id.parameters import ParameterSet


def register(subparsers: argparse._SubParsersAction) -> None:
    """Register the ``params`` subcommand (``show``, ``check``)."""
    parser = subparsers.add_parser(
        "params",
        help="show or check parameter files",
        description="Show a parameter file as a table (name, unit, value, description) or "
        "check that parameter files are valid.",
    )
    actions = parser.add_subparsers(dest="params_action", metavar="ACTION", required=True)
    show = actions.add_parser(
        "show",
        help="print a parameter file as a readable table",
        description="Print the header and every parameter (name, SI unit, value, description).",
    )
    show.add_argument("file", metavar="FILE", help="parameter file (YAML)")
    show.add_argument(
        "--json", action="store_true", help="print one JSON object (docs/cli-json.md)"
    )
    show.set_defaults(handler=run_show)
    check = actions.add_parser(
        "check",
        help="validate parameter files (exit 0 if all are valid, 2 otherwise)",
        description="Load and validate each file strictly; print one line per file.",
    )
    check.add_argument("files", metavar="FILE", nargs="+", help="parameter file(s) (YAML)")
    check.add_argument(
        "--json", action="store_true", help="print one JSON object (docs/cli-json.md)"
    )
    check.set_defaults(handler=run_check)


def format_table(params: ParameterSet) -> str:
    """The header lines and the parameter table of a parameter set."""
    from hframe_id.models import parameter_specs

    header = [
        ("file", str(params.path) if params.path else "-"),
        ("model", params.variant),
        ("title", params.title),
        ("source", params.source),
    ]
    header += [("reference", ref) for ref in params.references]
    if params.notes:
        header.append(("notes", params.notes))
    for key, value in params.provenance.items():
        header.append((f"provenance.{key}", str(value)))
    lines = [f"{key}: {value}" for key, value in header]
    rows = [  # the rows of analysis.export.parameter_rows, without importing SciPy
        (spec.name, spec.unit, repr(float(params.values[spec.name])), spec.description)
        for spec in parameter_specs(params.variant)
        if spec.name in params.values
    ]
    titles = ("name", "unit", "value", "description")
    widths = [max(len(t), *(len(r[i]) for r in rows)) for i, t in enumerate(titles)]

    def line(cells: tuple[str, ...]) -> str:
        name, unit, value, description = cells
        return (
            f"{name:<{widths[0]}}  {unit:<{widths[1]}}  {value:>{widths[2]}}  {description}"
        ).rstrip()

    lines += ["", line(titles), line(tuple("-" * w for w in widths))]
    lines += [line(row) for row in rows]
    return "\n".join(lines)


def run_show(args: argparse.Namespace) -> int:
    """Run ``hframe-id params show``: the file as a table of name, unit, value, description."""
    from hframe_id.parameters import load_parameter_file

    params = load_parameter_file(args.file)
    if args.json:
        from hframe_id.analysis.export import parameters_document

        emit("params show", parameters_document(params))
    else:
        print(format_table(params))
    return 0


def run_check(args: argparse.Namespace) -> int:
    """Run ``hframe-id params check``: exit status 0 if every file is valid, else 2."""
    from hframe_id.parameters import load_parameter_file

    files = []
    for path in args.files:
        try:
            params = load_parameter_file(path)
        except HframeIdError as err:
            files.append({"file": path, "ok": False, "error": str(err)})
            if not args.json:
                print(f"hframe-id: error: {err}", file=sys.stderr)
            continue
        files.append(
            {"file": path, "ok": True, "model": params.variant, "parameters": len(params.values)}
        )
        if not args.json:
            print(f"{path}: ok ({params.variant}, {len(params.values)} parameters)")
    failed = sum(not f["ok"] for f in files)
    if args.json:
        emit("params check", {"ok": not failed, "files": files})
    return 2 if failed else 0
