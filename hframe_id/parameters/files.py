"""Parameter files: a header plus every parameter value with its unit in its key.

Format (YAML, format_version 1.x)::

    format_version: "1.0"
    model: hframe-8                      # model variant
    model_file: ../models/my_axis.py     # optional: a user model's file, relative to this one
    title: H-frame 8th-order model, linear
    source: Sollmann 2007, Table 4.1     # where the values come from
    references: [...]                    # optional, list of strings
    notes: "..."                         # optional
    provenance: {...}                    # optional mapping (fits: id, data, solver, ...)
    uncertainty: {...}                   # optional mapping (fits: per-parameter statistics)
    parameters:
      "r [m]": 0.0194
      "k_l [N/m]": 13167.0
      ...

Values are SI. Loading is strict: unknown keys (with the nearest valid one suggested),
missing keys, non-finite or non-physical values, a wrong model variant and an unknown format
version are ``ParameterFileError`` naming the file, the key and the value. Saving writes a
temporary file and renames it, so a failed save never leaves half a file.
"""

from __future__ import annotations

import difflib
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from hframe_id.atomic import replace_atomically
from hframe_id.documents import load_yaml, read_text
from hframe_id.errors import ModelError, ParameterFileError, shown
from hframe_id.models import declaration, load_model_file, parameter_specs, variants

FORMAT_VERSION = "1.0"
SUPPORTED_MAJOR = 1

_REQUIRED_HEADER = ("format_version", "model", "title", "source", "parameters")
_OPTIONAL_HEADER = ("model_file", "references", "notes", "provenance", "uncertainty")


@dataclass
class ParameterSet:
    """SI parameter values of one model variant, with the file header that describes them."""

    variant: str
    values: dict[str, float]
    title: str
    source: str
    references: list[str] = field(default_factory=list)
    notes: str = ""
    provenance: dict[str, Any] = field(default_factory=dict)
    uncertainty: dict[str, Any] = field(default_factory=dict)
    path: Path | None = None

    def __post_init__(self) -> None:
        check_values(self.variant, self.values, self.path)

    def replace_values(self, **changes: float) -> ParameterSet:
        """A copy with some values changed (validated)."""
        values = dict(self.values)
        unknown = [name for name in changes if name not in values]
        if unknown:
            raise ParameterFileError(
                f"{self.where()}: no parameter(s) {', '.join(unknown)} in {self.variant}"
            )
        values.update({k: float(v) for k, v in changes.items()})
        return ParameterSet(
            self.variant, values, self.title, self.source, list(self.references), self.notes
        )

    def where(self) -> str:
        """Where the values come from, for messages: the file, else ``<variant parameters>``."""
        return str(self.path) if self.path else f"<{self.variant} parameters>"


def suggest(word: str, choices: list[str]) -> str:
    """`` (did you mean 'x'?)`` for the choice closest to a mistyped word, or ''."""
    close = difflib.get_close_matches(word, choices, n=1, cutoff=0.5)
    return f" (did you mean {close[0]!r}?)" if close else ""


def check_header(doc: Any, required: tuple[str, ...], optional: tuple[str, ...], where: str):
    """A YAML document is a mapping with every ``required`` header key and no key outside
    ``required + optional`` (``ParameterFileError`` naming the file and the key)."""
    if not isinstance(doc, Mapping):
        raise ParameterFileError(
            f"{where}: expected a YAML mapping with a header, got {shown(doc)}"
        )
    allowed = required + optional
    for key in doc:
        if key not in allowed:
            raise ParameterFileError(
                f"{where}: unknown header key {shown(key)}{suggest(str(key), list(allowed))}"
            )
    for key in required:
        if key not in doc:
            raise ParameterFileError(f"{where}: missing header key {shown(key)}")


def most_extreme(values: Mapping[str, float]) -> str:
    """``name = value`` of the value farthest from 1 in orders of magnitude: what an error
    about values that cannot be computed with (no poles, no stable step) points at."""
    name = max((n for n in values if values[n]), key=lambda n: abs(math.log10(abs(values[n]))))
    return f"{name} = {values[name]:g}"


def check_values(variant: str, values: Mapping[str, float], path: Path | None = None) -> None:
    """Validate SI values by parameter name: all required present, none unknown, physical."""
    where = str(path) if path else f"<{variant} parameters>"
    try:
        specs = {spec.name: spec for spec in parameter_specs(variant)}
    except ModelError as err:
        raise ParameterFileError(f"{where}: {err}") from None
    for name in values:
        if name not in specs:
            raise ParameterFileError(
                f"{where}: unknown parameter {shown(name)}{suggest(name, list(specs))}"
            )
    for spec in specs.values():
        if spec.required and spec.name not in values:
            raise ParameterFileError(f"{where}: missing parameter {spec.key!r}")
    for name, value in values.items():
        spec = specs[name]
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ParameterFileError(f"{where}: {spec.key} must be a number, got {shown(value)}")
        if not math.isfinite(value):
            raise ParameterFileError(f"{where}: {spec.key} must be finite, got {shown(value)}")
        if spec.kind == "positive" and value <= 0:
            raise ParameterFileError(f"{where}: {spec.key} must be > 0, got {shown(value)}")
        if spec.kind == "nonnegative" and value < 0:
            raise ParameterFileError(f"{where}: {spec.key} must be >= 0, got {shown(value)}")


def _check_format_version(raw: Any, where: str) -> None:
    major = str(raw).split(".")[0] if isinstance(raw, str | int | float) else ""
    if not major.isdigit():
        raise ParameterFileError(f"{where}: format_version must look like '1.0', got {shown(raw)}")
    if major.lstrip("0") != str(SUPPORTED_MAJOR):
        raise ParameterFileError(
            f"{where}: unknown format_version {shown(raw)}; this hframe-id reads "
            f"{SUPPORTED_MAJOR}.x files"
        )


def _values_from_keys(variant: str, raw: Any, where: str) -> dict[str, float]:
    if not isinstance(raw, Mapping):
        raise ParameterFileError(f"{where}: 'parameters' must be a mapping of 'name [unit]': value")
    by_key = {spec.key: spec for spec in parameter_specs(variant)}
    values = {}
    for key, value in raw.items():
        if key not in by_key:
            raise ParameterFileError(
                f"{where}: unknown parameter key {shown(key)} (value {shown(value)})"
                f"{suggest(str(key), list(by_key))} for model {variant}"
            )
        values[by_key[key].name] = value
    return values


#: The numbers of a parameter's entry in a fit's ``uncertainty.parameters`` that others read
#: (``design`` draws around the estimate by the standard error): a number or null each.
_UNCERTAINTY_NUMBERS = ("estimate", "std_error")


def _check_uncertainty(uncertainty: Mapping[str, Any], where: str) -> None:
    """A fit's ``uncertainty.parameters``, if there, is a mapping of parameter to a mapping
    whose ``_UNCERTAINTY_NUMBERS`` are numbers or null (``parameters: [1, 2]`` or an entry
    ``k_l [N/m]: 5`` made ``design --params`` end in an AttributeError traceback)."""
    listed = uncertainty.get("parameters", {})
    if not isinstance(listed, Mapping):
        raise ParameterFileError(f"{where}: uncertainty.parameters must be a mapping")
    for name, entry in listed.items():
        if not isinstance(entry, Mapping):
            raise ParameterFileError(
                f"{where}: uncertainty.parameters.{shown(name)} must be a mapping, got "
                f"{shown(entry)}"
            )
        for key in _UNCERTAINTY_NUMBERS:
            value = entry.get(key)
            if value is not None and (
                isinstance(value, bool) or not isinstance(value, int | float)
            ):
                raise ParameterFileError(
                    f"{where}: uncertainty.parameters.{shown(name)}.{key} must be a number or "
                    f"null, got {shown(value)}"
                )


def load_parameter_file(path: str | os.PathLike, variant: str | None = None) -> ParameterSet:
    """Load and validate a parameter file.

    Parameters
    ----------
    path : the YAML file.
    variant : if given, the file must describe this model variant.
    """
    path = Path(path)
    where = str(path)
    try:
        text = read_text(path, "parameter file", ParameterFileError)
    except FileNotFoundError:
        raise ParameterFileError(f"{where}: no such parameter file") from None
    except OSError as err:
        raise ParameterFileError(f"{where}: cannot read ({err.strerror})") from None
    doc = load_yaml(text, where, ParameterFileError)
    check_header(doc, _REQUIRED_HEADER, _OPTIONAL_HEADER, where)
    _check_format_version(doc["format_version"], where)
    model = doc["model"]
    # Checked first: a file of another model is refused without running its model file
    # (the fit's known points look through every parameter file beside the reference).
    if variant is not None and model != variant:
        raise ParameterFileError(
            f"{where}: model is {shown(model)}, but {variant!r} is needed here"
        )
    if model not in variants() and "model_file" in doc:
        load_model_file(path.parent / str(doc["model_file"]))
    known = variants()
    if model not in known:
        raise ParameterFileError(
            f"{where}: model {shown(model)} is not a variant{suggest(str(model), list(known))};"
            f" valid: {', '.join(known)} (a model of your own: --model-file FILE.py)"
        )
    for key in ("references",):
        if key in doc and not isinstance(doc[key], list):
            raise ParameterFileError(f"{where}: {shown(key)} must be a list")
    for key in ("provenance", "uncertainty"):
        if key in doc and not isinstance(doc[key], Mapping):
            raise ParameterFileError(f"{where}: {shown(key)} must be a mapping")
    _check_uncertainty(doc.get("uncertainty", {}), where)
    values = _values_from_keys(model, doc["parameters"], where)
    return ParameterSet(
        variant=model,
        values=values,
        title=str(doc["title"]),
        source=str(doc["source"]),
        references=list(doc.get("references", [])),
        notes=str(doc.get("notes", "")),
        provenance=dict(doc.get("provenance", {})),
        uncertainty=dict(doc.get("uncertainty", {})),
        path=path,
    )


def to_document(params: ParameterSet) -> dict[str, Any]:
    """The YAML document of a parameter set (header first, values keyed 'name [unit]')."""
    check_values(params.variant, params.values, params.path)
    doc: dict[str, Any] = {
        "format_version": FORMAT_VERSION,
        "model": params.variant,
        "title": params.title,
        "source": params.source,
    }
    if params.references:
        doc["references"] = list(params.references)
    if params.notes:
        doc["notes"] = params.notes
    if params.provenance:
        doc["provenance"] = params.provenance
    if params.uncertainty:
        doc["uncertainty"] = params.uncertainty
    doc["parameters"] = {
        spec.key: float(params.values[spec.name])
        for spec in parameter_specs(params.variant)
        if spec.name in params.values
    }
    return doc


def save_parameter_file(
    params: ParameterSet, path: str | os.PathLike, overwrite: bool = False
) -> Path:
    """Write a parameter file atomically (temporary file, then rename).

    Refuses to replace an existing file unless ``overwrite`` is true.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise ParameterFileError(f"{path}: exists already; refusing to overwrite it")
    doc = to_document(params)
    model_file = declaration(params.variant).model_file
    if model_file is not None:
        # A user model's file, relative to the parameter file, so that readers find the model.
        relative = os.path.relpath(model_file, path.resolve().parent)
        doc = {**dict(list(doc.items())[:2]), "model_file": relative, **doc}
    text = yaml.safe_dump(doc, sort_keys=False, allow_unicode=True, width=100)
    path.parent.mkdir(parents=True, exist_ok=True)
    return replace_atomically(path, text)
