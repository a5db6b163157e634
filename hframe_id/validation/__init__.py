"""Model validation as control engineers know it from MATLAB's ``compare`` and ``resid``:
simulation fit [%], k-step-ahead prediction fit [%], residual whiteness and independence from
the inputs with 99 % bands, plots, and leave-one-recording-out cross-validation
(docs/validation.md).

    from hframe_id.validation import ValidationOptions, validate
    result = validate([fitted, table], recordings, ValidationOptions(horizon=10))
"""

from hframe_id.validation.compare import (
    ChannelResult,
    RecordingResult,
    RunResult,
    ValidationOptions,
    ValidationResult,
    validate,
)
from hframe_id.validation.metrics import fit_percent

__all__ = [
    "ChannelResult",
    "RecordingResult",
    "RunResult",
    "ValidationOptions",
    "ValidationResult",
    "fit_percent",
    "validate",
]
