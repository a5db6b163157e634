"""Parameters and linear models in the forms other tools read (JSON, CSV, MATLAB, python-control).

Two kinds of export:

* **parameters** (``json``, ``csv``): every value of a parameter file with its name, SI unit and
  description, plus the file's header (model variant, title, source);
* **state space** (``statespace``, ``matlab``, ``matlab-script``, ``python-control``): the
  linearization about rest (``hframe_id.analysis.linear.linearize``; Coulomb friction excluded,
  with a note) as A, B, C, D with state, input and output names and units. Time is continuous,
  in seconds; all signals are SI (m, rad, V).

``matlab`` writes a MAT-file (``scipy.io.savemat``, format 5) holding ``A``, ``B``, ``C``,
``D``, the cell arrays ``StateName``, ``StateUnit``, ``InputName``, ``InputUnit``,
``OutputName``, ``OutputUnit`` (the names of MATLAB's ``ss`` properties), the parameter values
as a struct ``params`` and their units as ``param_units``. In MATLAB::

    load hframe8.mat
    sys = ss(A, B, C, D, 'StateName', StateName, 'StateUnit', StateUnit, ...
             'InputName', InputName, 'InputUnit', InputUnit, ...
             'OutputName', OutputName, 'OutputUnit', OutputUnit);

and in Python ``scipy.io.loadmat`` then ``control.ss(m["A"], m["B"], m["C"], m["D"])``.
``matlab-script`` writes the same as a ``.m`` script that builds ``sys`` directly, and
``python-control`` a Python module with numpy arrays and a function ``ss()`` returning a named
``control.StateSpace``. Numbers are written with ``repr`` (shortest round-trip form), so every
text export reproduces the float64 matrices exactly.

This module builds the documents; ``write_atomic`` writes them (temporary file, then rename;
never over an existing file unless asked).
"""

from __future__ import annotations

import csv
import io
import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hframe_id import __version__
from hframe_id.analysis.formats import FORMATS, ExportFormat
from hframe_id.atomic import replace_atomically
from hframe_id.errors import ModelError, OptionError
from hframe_id.models import parameter_specs
from hframe_id.parameters import ParameterSet
from hframe_id.parameters.files import suggest

if TYPE_CHECKING:
    from hframe_id.analysis.linear import LinearModel

#: Units of the pole-zero report.
POLE_ZERO_UNITS = {
    "poles": "rad/s",
    "zeros": "rad/s",
    "natural_frequencies": "rad/s",
    "damping": "1",
}


def export_format(name: str) -> ExportFormat:
    """The export format called ``name``; an unknown name is an ``OptionError`` with a hint."""
    if name not in FORMATS:
        raise OptionError(
            f"unknown export format {name!r}{suggest(name, list(FORMATS))}; "
            f"valid: {', '.join(FORMATS)}"
        )
    return FORMATS[name]


def resolve_signal(names: Sequence[str], name: str, kind: str, variant: str) -> str:
    """Check that ``name`` is one of a model's input or output names (``kind``)."""
    if name not in names:
        raise ModelError(
            f"{variant} has no {kind} named {name!r}{suggest(name, list(names))}; "
            f"valid: {', '.join(names)}"
        )
    return name


def _header(params: ParameterSet, notes_key: str = "notes") -> dict[str, Any]:
    """Header fields of a parameter set; its free-text notes go under ``notes_key``."""
    header: dict[str, Any] = {
        "model": params.variant,
        "title": params.title,
        "source": params.source,
    }
    if params.path is not None:
        header["file"] = str(params.path)
    if params.references:
        header["references"] = list(params.references)
    if params.notes:
        header[notes_key] = params.notes
    return header


# --- parameters -----------------------------------------------------------------------------


def parameter_rows(params: ParameterSet) -> list[dict[str, Any]]:
    """One row per parameter in the file, in the model's order: name, unit, value, description."""
    return [
        {
            "name": spec.name,
            "unit": spec.unit,
            "value": float(params.values[spec.name]),
            "description": spec.description,
        }
        for spec in parameter_specs(params.variant)
        if spec.name in params.values
    ]


def parameters_document(params: ParameterSet) -> dict[str, Any]:
    """Header plus every parameter (name, SI unit, value, description)."""
    doc = _header(params)
    if params.provenance:
        doc["provenance"] = params.provenance
    if params.uncertainty:
        doc["uncertainty"] = params.uncertainty
    doc["parameters"] = parameter_rows(params)
    return doc


def parameters_json(params: ParameterSet) -> str:
    """The ``json`` format: ``parameters_document`` as indented JSON text."""
    return json.dumps(parameters_document(params), indent=2) + "\n"


def parameters_csv(params: ParameterSet) -> str:
    """The ``csv`` format: a header and one ``name,unit,value,description`` row per
    parameter (values in SI units)."""
    buffer = io.StringIO()
    writer = csv.DictWriter(
        buffer, fieldnames=["name", "unit", "value", "description"], lineterminator="\n"
    )
    writer.writeheader()
    for row in parameter_rows(params):
        writer.writerow({**row, "value": repr(row["value"])})
    return buffer.getvalue()


# --- state space ----------------------------------------------------------------------------


def statespace_document(params: ParameterSet, lin: LinearModel) -> dict[str, Any]:
    """A, B, C, D (row lists) with named, unit-carrying states, inputs and outputs."""

    def signals(names: Sequence[str], units: Sequence[str]) -> list[dict[str, str]]:
        return [{"name": n, "unit": u} for n, u in zip(names, units, strict=True)]

    doc = _header(params, notes_key="file_notes")
    doc.update(
        {
            "linearization": "about rest (x = 0, u = 0); continuous time, seconds; SI units",
            "states": signals(lin.states, lin.state_units),
            "inputs": signals(lin.inputs, lin.input_units),
            "outputs": signals(lin.outputs, lin.output_units),
            "A": lin.A.tolist(),
            "B": lin.B.tolist(),
            "C": lin.C.tolist(),
            "D": lin.D.tolist(),
            "notes": list(lin.notes),
            "generator": f"hframe-id {__version__}",
        }
    )
    return doc


def statespace_json(params: ParameterSet, lin: LinearModel) -> str:
    """The ``statespace`` format: ``statespace_document`` (A, B, C, D with the state, input
    and output names and units) as indented JSON text."""
    return json.dumps(statespace_document(params, lin), indent=2) + "\n"


def _cell(strings: Sequence[str]) -> np.ndarray:
    """A column cell array for savemat."""
    cell = np.empty((len(strings), 1), dtype=object)
    for i, text in enumerate(strings):
        cell[i, 0] = text
    return cell


def mat_bytes(params: ParameterSet, lin: LinearModel) -> bytes:
    """A MATLAB MAT-file (v5) with A, B, C, D, names, units and the parameter values."""
    rows = parameter_rows(params)
    contents = {
        "A": lin.A,
        "B": lin.B,
        "C": lin.C,
        "D": lin.D,
        "StateName": _cell(lin.states),
        "StateUnit": _cell(lin.state_units),
        "InputName": _cell(lin.inputs),
        "InputUnit": _cell(lin.input_units),
        "OutputName": _cell(lin.outputs),
        "OutputUnit": _cell(lin.output_units),
        "TimeUnit": "seconds",
        "model": params.variant,
        "title": params.title,
        "source": params.source,
        "notes": _cell(lin.notes),
        "params": {row["name"]: row["value"] for row in rows},
        "param_units": {row["name"]: row["unit"] for row in rows},
        "generator": f"hframe-id {__version__}",
    }
    buffer = io.BytesIO()
    import scipy.io  # here: 0.2 s that --help and the text formats need not pay

    scipy.io.savemat(buffer, contents, format="5", oned_as="column")
    return buffer.getvalue()


def _matlab_matrix(matrix: np.ndarray) -> str:
    rows = ["    " + " ".join(repr(float(v)) for v in row) for row in matrix]
    return "[\n" + ";\n".join(rows) + "\n]"


def _matlab_cell(strings: Sequence[str]) -> str:
    return "{" + "; ".join("'" + s.replace("'", "''") + "'" for s in strings) + "}"


def _comment_lines(params: ParameterSet, lin: LinearModel, prefix: str) -> list[str]:
    lines = [
        f"{params.variant}: {params.title}",
        f"Source: {params.source}",
        "Linearized about rest (x = 0, u = 0); continuous time [s]; SI units.",
        *lin.notes,
        f"Generated by hframe-id {__version__}.",
    ]
    return [f"{prefix} {line}".rstrip() for line in lines]


def matlab_script(params: ParameterSet, lin: LinearModel) -> str:
    """A MATLAB script that defines A, B, C, D and ``sys = ss(...)`` with names and units."""
    out = _comment_lines(params, lin, "%")
    for name, matrix in (("A", lin.A), ("B", lin.B), ("C", lin.C), ("D", lin.D)):
        out.append(f"{name} = {_matlab_matrix(matrix)};")
    out.append(
        "sys = ss(A, B, C, D, ...\n"
        f"    'StateName', {_matlab_cell(lin.states)}, ...\n"
        f"    'StateUnit', {_matlab_cell(lin.state_units)}, ...\n"
        f"    'InputName', {_matlab_cell(lin.inputs)}, ...\n"
        f"    'InputUnit', {_matlab_cell(lin.input_units)}, ...\n"
        f"    'OutputName', {_matlab_cell(lin.outputs)}, ...\n"
        f"    'OutputUnit', {_matlab_cell(lin.output_units)}, ...\n"
        f"    'TimeUnit', 'seconds', 'Name', '{params.variant}');"
    )
    return "\n".join(out) + "\n"


def python_control_script(params: ParameterSet, lin: LinearModel) -> str:
    """A Python module: numpy A, B, C, D, signal names and units, and ``ss()`` for python-control.

    The module imports only numpy; ``ss()`` imports ``control`` when called.
    """

    def array(matrix: np.ndarray) -> str:
        rows = ",\n".join(
            "        [" + ", ".join(repr(float(v)) for v in row) + "]" for row in matrix
        )
        return f"np.array(\n    [\n{rows},\n    ]\n)"

    doc = "\n".join(line[2:] for line in _comment_lines(params, lin, "#"))
    out = [f'"""{doc}\n"""', "", "import numpy as np", ""]
    for name, matrix in (("A", lin.A), ("B", lin.B), ("C", lin.C), ("D", lin.D)):
        out.append(f"{name} = {array(matrix)}")
    for name, values in (
        ("STATES", lin.states),
        ("STATE_UNITS", lin.state_units),
        ("INPUTS", lin.inputs),
        ("INPUT_UNITS", lin.input_units),
        ("OUTPUTS", lin.outputs),
        ("OUTPUT_UNITS", lin.output_units),
    ):
        out.append(f"{name} = {tuple(values)!r}")
    out += [
        "",
        "",
        "def ss():",
        '    """The model as a python-control StateSpace with named signals."""',
        "    import control",
        "",
        "    return control.ss(",
        "        A, B, C, D, states=list(STATES), inputs=list(INPUTS), outputs=list(OUTPUTS),",
        f"        name={params.variant!r},",
        "    )",
    ]
    return "\n".join(out) + "\n"


# --- pole-zero report -----------------------------------------------------------------------


def _complex_list(values: np.ndarray) -> list[list[float]]:
    return [[float(z.real), float(z.imag)] for z in values]


def _frequencies(values: np.ndarray) -> dict[str, list[float]]:
    from hframe_id.analysis.linear import natural_frequency_and_damping

    pairs = natural_frequency_and_damping(values)
    return {
        "natural_frequencies": [omega for omega, _ in pairs],
        "damping": [zeta for _, zeta in pairs],
    }


def pole_zero_report(
    params: ParameterSet,
    lin: LinearModel | None = None,
    inputs: Sequence[str] | None = None,
    outputs: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Poles of the linearization about rest and the zeros of each selected input -> output.

    ``poles`` are the eigenvalues of A (the same for every pair, as in Table 5.2); with exactly
    one pair the report also has top-level ``input``, ``output`` and ``zeros``. ``pairs`` lists
    every selected pair's zeros. Natural frequencies [rad/s] and damping ratios are given for
    poles and zeros alike.
    """
    from hframe_id.analysis.linear import linearize

    lin = lin or linearize(params)
    inputs = list(inputs) if inputs else list(lin.inputs)
    outputs = list(outputs) if outputs else list(lin.outputs)
    for name in inputs:
        resolve_signal(lin.inputs, name, "input", params.variant)
    for name in outputs:
        resolve_signal(lin.outputs, name, "output", params.variant)
    poles = lin.poles()
    report = _header(params, notes_key="file_notes")
    report.update({"units": dict(POLE_ZERO_UNITS), "poles": _complex_list(poles)})
    report.update(_frequencies(poles))
    pairs = []
    for i in inputs:
        for o in outputs:
            zeros = lin.siso(i, o).zeros()
            pairs.append(
                {
                    "input": i,
                    "output": o,
                    "input_unit": lin.input_units[lin.inputs.index(i)],
                    "output_unit": lin.output_units[lin.outputs.index(o)],
                    "zeros": _complex_list(zeros),
                    "zero_frequencies": _frequencies(zeros),
                }
            )
    if len(pairs) == 1:
        pair = pairs[0]
        report.update(
            {
                "input": pair["input"],
                "output": pair["output"],
                "zeros": pair["zeros"],
                "zero_natural_frequencies": pair["zero_frequencies"]["natural_frequencies"],
                "zero_damping": pair["zero_frequencies"]["damping"],
            }
        )
    report["pairs"] = pairs
    report["notes"] = list(lin.notes)
    return report


# --- files ----------------------------------------------------------------------------------


def render(params: ParameterSet, fmt: str | ExportFormat) -> str | bytes:
    """The export of a parameter set in one format (text, or bytes for binary formats)."""
    fmt = fmt if isinstance(fmt, ExportFormat) else export_format(fmt)
    if fmt.name == "json":
        return parameters_json(params)
    if fmt.name == "csv":
        return parameters_csv(params)
    from hframe_id.analysis.linear import linearize

    lin = linearize(params)
    return {
        "statespace": statespace_json,
        "matlab": mat_bytes,
        "matlab-script": matlab_script,
        "python-control": python_control_script,
    }[fmt.name](params, lin)


def write_atomic(path: str | os.PathLike, data: str | bytes, overwrite: bool = False) -> Path:
    """Write ``data`` to ``path`` by a temporary file and a rename.

    An existing file is kept (``OptionError``) unless ``overwrite``; a failed write leaves
    neither a partial file nor the temporary one.
    """
    path = Path(path)
    if path.is_dir():
        raise OptionError(f"{path}: is a directory; give a file name")
    if path.exists() and not overwrite:
        raise OptionError(f"{path}: exists already; use --force to overwrite it")
    if not path.parent.is_dir():
        raise OptionError(f"{path}: directory {path.parent} does not exist")
    return replace_atomically(path, data)
