"""Recordings: the validated in-memory ``Recording``, the MCAP log format (docs/log-format.md),
its crash-safe writer and validating reader, and the rig's sensor models. Rigs, protocols and
the logger that make recordings live in ``hframe_id.rig``.

The names below are loaded on first use (PEP 562): the light modules of the package (log
format, units, import specifications) can be imported, e.g. for ``hframe-id import --help``,
without the reader's NumPy, MCAP and parameter machinery.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from hframe_id.recordings.reader import (
        SequenceGapWarning,
        TruncatedRecordingWarning,
        read_recording,
    )
    from hframe_id.recordings.recording import Recording

_HOMES = {
    "SequenceGapWarning": "hframe_id.recordings.reader",
    "TruncatedRecordingWarning": "hframe_id.recordings.reader",
    "read_recording": "hframe_id.recordings.reader",
    "Recording": "hframe_id.recordings.recording",
}

__all__ = ["Recording", "SequenceGapWarning", "TruncatedRecordingWarning", "read_recording"]


def __getattr__(name: str):
    if name not in _HOMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(_HOMES[name]), name)
