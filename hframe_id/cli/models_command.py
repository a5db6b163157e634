"""``hframe-id models``: list the model variants with their states, inputs, outputs, parameters."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    """Register the ``models`` subcommand."""
    parser = subparsers.add_parser(
        "models",
        help="list model variants and their signals and parameters",
        description="List the model variants with their states, inputs, outputs and "
        "parameters (names with SI units).",
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    parser.set_defaults(handler=run)


def describe(variant: str) -> dict:
    """A variant as ``hframe-id models`` shows it: signals and parameters with their units."""
    from hframe_id.models import build_model, declaration, parameter_specs

    model = build_model(variant)
    return {
        "variant": variant,
        "description": model.description,
        "declared_in": declaration(variant).source,
        "reference": str(declaration(variant).reference_file or ""),
        "states": [s.label for s in model.states],
        "inputs": [s.label for s in model.inputs],
        "outputs": [s.label for s in model.outputs],
        "parameters": [
            spec.key + ("" if spec.required else " (position-dependent stiffness only)")
            for spec in parameter_specs(variant)
        ],
    }


def run(args: argparse.Namespace) -> int:
    """Run ``hframe-id models``: every variant as text or JSON."""
    from hframe_id.models import variants

    described = [describe(v) for v in variants()]
    if args.json:
        from hframe_id.cli import json_output

        print(json_output.text(described))
        return 0
    for item in described:
        print(f"{item['variant']}: {item['description']}")
        for field in ("states", "inputs", "outputs", "parameters"):
            print(f"  {field}: {', '.join(item[field])}")
        print()
    return 0
