"""``--json`` output of the commands: one JSON object on stdout, in a versioned envelope
(docs/cli-json.md). Numbers that are not finite become null; paths become strings."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from hframe_id import __version__

#: Raised when a key is removed or changes meaning; adding keys keeps the version.
SCHEMA_VERSION = 1


def _plain(value: Any) -> Any:
    """``value`` as JSON types: NumPy scalars and arrays unwrapped, NaN and inf as None."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    if hasattr(value, "tolist"):  # NumPy scalar or array
        return _plain(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def text(document: Any) -> str:
    """``document`` as indented JSON by the one rule of every command's ``--json``: NaN and
    infinities as null (``json.dumps`` wrote ``Infinity``, which no JSON reader accepts,
    for a drift against a baseline of zero in ``fleet report --json``)."""
    return json.dumps(_plain(document), indent=2, allow_nan=False)


def dumps(command: str, payload: Mapping[str, Any]) -> str:
    """The JSON text of ``command``'s result: ``{"schema_version", "command", "software",
    **payload}``."""
    document = {
        "schema_version": SCHEMA_VERSION,
        "command": command,
        "software": f"hframe-id {__version__}",
        **payload,
    }
    return text(document)


def emit(command: str, payload: Mapping[str, Any]) -> None:
    """Print ``command``'s result as one JSON object on stdout."""
    print(dumps(command, payload))
