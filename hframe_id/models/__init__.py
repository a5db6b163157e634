"""Symbolic models of the one-axis drive and the H-frame, derived by Lagrange's equations.

Every variant is a ``ModelDeclaration`` in one registry (``hframe_id.models.registry``): the
thesis's three below, plug-ins of the entry-point group ``hframe_id.models``, and user model
files (``load_model_file``, docs/custom-models.md).
"""

from __future__ import annotations

from functools import lru_cache

from hframe_id.models import hframe8, hframe20, one_axis
from hframe_id.models.declaration import ModelDeclaration, Output
from hframe_id.models.lagrange import Friction, LagrangianSystem
from hframe_id.models.model import Model, freeze
from hframe_id.models.options import ModelOptions
from hframe_id.models.registry import declaration, register, variants
from hframe_id.models.spec import ParameterSpec, Signal
from hframe_id.models.user import declare, load_model_file, sibling_module

#: The thesis's variants (built in; ``variants()`` also lists plug-ins and loaded model files).
VARIANTS: tuple[str, ...] = tuple(
    register(m.DECLARATION).name for m in (one_axis, hframe20, hframe8)
)
#: Built-in variants beyond the thesis's: hframe-8 with current-limited amplifiers.
EXTENDED_VARIANTS: tuple[str, ...] = (register(hframe8.CURRENT_LIMITED).name,)

__all__ = [
    "EXTENDED_VARIANTS",
    "VARIANTS",
    "Friction",
    "LagrangianSystem",
    "Model",
    "ModelDeclaration",
    "ModelOptions",
    "Output",
    "ParameterSpec",
    "Signal",
    "build_model",
    "declaration",
    "declare",
    "load_model_file",
    "parameter_specs",
    "register",
    "sibling_module",
    "variants",
]


def parameter_specs(variant: str) -> tuple[ParameterSpec, ...]:
    """Every parameter a file of this variant may hold (required and option-dependent)."""
    return declaration(variant).parameters


@lru_cache(maxsize=32)
def _build(declared: ModelDeclaration, options: ModelOptions) -> Model:
    return freeze(declared, options)


def build_model(variant: str, options: ModelOptions | None = None) -> Model:
    """Derive (once per declaration and options) and return the symbolic model."""
    return _build(declaration(variant), options or ModelOptions())
