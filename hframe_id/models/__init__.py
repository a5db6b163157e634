"""Symbolic models of the one-axis drive and the H-frame, derived by Lagrange's equations."""

from __future__ import annotations

import difflib
from functools import lru_cache
from types import ModuleType

from hframe_id.errors import ModelError
from hframe_id.models import hframe8, hframe20, one_axis
from hframe_id.models.model import Model, freeze
from hframe_id.models.options import ModelOptions
from hframe_id.models.spec import ParameterSpec, Signal

_VARIANTS: dict[str, ModuleType] = {m.NAME: m for m in (one_axis, hframe20, hframe8)}
VARIANTS: tuple[str, ...] = tuple(_VARIANTS)

__all__ = [
    "VARIANTS",
    "Model",
    "ModelOptions",
    "ParameterSpec",
    "Signal",
    "build_model",
    "parameter_specs",
]


def _variant_module(variant: str) -> ModuleType:
    if variant not in _VARIANTS:
        close = difflib.get_close_matches(str(variant), VARIANTS, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ModelError(f"unknown model variant {variant!r}{hint}; valid: {', '.join(VARIANTS)}")
    return _VARIANTS[variant]


def parameter_specs(variant: str) -> tuple[ParameterSpec, ...]:
    """Every parameter a file of this variant may hold (required and option-dependent)."""
    return _variant_module(variant).PARAMETERS


@lru_cache(maxsize=32)
def build_model(variant: str, options: ModelOptions | None = None) -> Model:
    """Derive (once per variant and options) and return the symbolic model."""
    module = _variant_module(variant)
    options = options or ModelOptions()
    used = tuple(
        spec for spec in module.PARAMETERS if spec.required or options.position_dependent_stiffness
    )
    return freeze(
        module.NAME,
        module.DESCRIPTION,
        options,
        used,
        module.INPUTS,
        module.OUTPUTS,
        module.lagrangian,
    )
