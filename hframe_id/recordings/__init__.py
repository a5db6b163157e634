"""Recordings: the validated in-memory ``Recording``, the MCAP log format (docs/log-format.md),
its crash-safe writer and validating reader, and the rig's sensor models. Rigs, protocols and
the logger that make recordings live in ``hframe_id.rig``.
"""

from hframe_id.recordings.reader import (
    SequenceGapWarning,
    TruncatedRecordingWarning,
    read_recording,
)
from hframe_id.recordings.recording import Recording

__all__ = ["Recording", "SequenceGapWarning", "TruncatedRecordingWarning", "read_recording"]
