"""The one registry of model variants: the thesis's three, user model files, entry points.

Variants are looked up by name. Besides the built-in declarations, a package may register
models through the entry-point group ``hframe_id.models`` (each entry point loads a
``ModelDeclaration``), and a user's model file (``--model-file``) registers its declaration
when loaded (``hframe_id.models.user.load_model_file``).
"""

from __future__ import annotations

import difflib
from functools import cache
from importlib.metadata import entry_points

from hframe_id.errors import ModelError
from hframe_id.models.declaration import ModelDeclaration

ENTRY_POINT_GROUP = "hframe_id.models"

_REGISTERED: dict[str, ModelDeclaration] = {}


def register(declaration: ModelDeclaration) -> ModelDeclaration:
    """Add a declaration under its name; registering the same declaration again is a no-op.

    A different declaration under a taken name is an error (names are how files, recordings
    and fits refer to a model).
    """
    if not isinstance(declaration, ModelDeclaration):
        raise ModelError(f"cannot register {declaration!r}: not a ModelDeclaration")
    known = _REGISTERED.get(declaration.name)
    if known is not None and known != declaration and known.source != declaration.source:
        raise ModelError(
            f"{declaration.source}: model name {declaration.name!r} is already taken by "
            f"{known.source}"
        )
    _REGISTERED[declaration.name] = declaration
    return declaration


@cache
def _load_entry_points() -> None:
    for entry in entry_points(group=ENTRY_POINT_GROUP):
        try:
            declaration = entry.load()
        except Exception as err:  # a broken plug-in must not take the others down
            raise ModelError(
                f"entry point {entry.name!r} ({entry.value}) of group {ENTRY_POINT_GROUP} "
                f"failed to load: {err}"
            ) from err
        register(declaration)


def variants() -> tuple[str, ...]:
    """Names of every registered variant (built-in first, then plug-ins and model files)."""
    _load_entry_points()
    return tuple(_REGISTERED)


def declaration(name: str) -> ModelDeclaration:
    """The declaration of variant ``name``; unknown names suggest the nearest."""
    if name not in _REGISTERED:
        _load_entry_points()
    if name not in _REGISTERED:
        close = difflib.get_close_matches(str(name), list(_REGISTERED), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ModelError(
            f"unknown model variant {name!r}{hint}; valid: "
            f"{', '.join(_REGISTERED)} (a model of your own: --model-file FILE.py)"
        )
    return _REGISTERED[name]
