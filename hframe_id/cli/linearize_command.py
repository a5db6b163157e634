"""``hframe-id linearize FILE``: poles, zeros, natural frequencies and damping about rest."""

from __future__ import annotations

import argparse

from hframe_id.errors import ParameterFileError


def register(subparsers: argparse._SubParsersAction) -> None:
    """Register the ``linearize`` subcommand."""
    parser = subparsers.add_parser(
        "linearize",
        help="poles and zeros of the model linearized about rest",
        description="Linearize the model of a parameter file about rest and print the poles "
        "(eigenvalues of A) and the zeros of each input -> output pair, with natural "
        "frequencies [rad/s] and damping ratios. Coulomb friction has no linearization at rest "
        "and is excluded (the output says so when the file has any).",
    )
    parser.add_argument("file", metavar="FILE", help="parameter file (YAML); names the model")
    parser.add_argument("--input", metavar="NAME", help="input, e.g. u1 (default: all)")
    parser.add_argument("--output", metavar="NAME", help="output, e.g. phi1 (default: all)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    parser.set_defaults(handler=run)


def _complex(value: list[float]) -> str:
    re, im = value
    return f"{re:12.4f} {'+' if im >= 0 else '-'} {abs(im):10.4f}i"


def _table(values: list[list[float]], omegas: list[float], zetas: list[float]) -> list[str]:
    lines = [f"    {'value [rad/s]':>27}  {'omega_n [rad/s]':>15}  {'zeta':>8}"]
    for value, omega, zeta in zip(values, omegas, zetas, strict=True):
        lines.append(f"    {_complex(value)}  {omega:15.4f}  {zeta:8.4f}")
    return lines or ["    (none)"]


def format_text(report: dict) -> str:
    """The text form of a ``pole_zero_report``: poles, then the zeros of each input -> output pair.

    Each with its natural frequency [rad/s] and damping ratio [-].
    """
    lines = [f"{report['model']}: {report['title']} ({report['source']})"]
    lines.append("linearized about rest (x = 0, u = 0)")
    lines += [f"note: {note}" for note in report["notes"]]
    lines.append(f"poles ({len(report['poles'])}):")
    lines += _table(report["poles"], report["natural_frequencies"], report["damping"])
    for pair in report["pairs"]:
        zeros = pair["zeros"]
        lines.append(
            f"zeros of {pair['input']} [{pair['input_unit']}] -> "
            f"{pair['output']} [{pair['output_unit']}] ({len(zeros)}):"
        )
        freq = pair["zero_frequencies"]
        lines += (
            _table(zeros, freq["natural_frequencies"], freq["damping"]) if zeros else ["    (none)"]
        )
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    """Run ``hframe-id linearize``: the pole-zero report as text or JSON."""
    import numpy as np

    from hframe_id.analysis.export import pole_zero_report
    from hframe_id.parameters import load_parameter_file
    from hframe_id.parameters.files import most_extreme

    params = load_parameter_file(args.file)
    try:
        report = pole_zero_report(
            params,
            inputs=[args.input] if args.input else None,
            outputs=[args.output] if args.output else None,
        )
    except np.linalg.LinAlgError as err:
        raise ParameterFileError(
            f"{args.file}: no poles and zeros for these values ({err}); the most extreme is "
            f"{most_extreme(params.values)}"
        ) from None
    if args.json:
        from hframe_id.cli import json_output

        print(json_output.text(report))
    else:
        print(format_text(report))
    return 0
