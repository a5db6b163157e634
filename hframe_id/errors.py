"""Typed errors raised at the edges of hframe-id.

Every error names what is at fault (file, field, value) so that the command line can print
it as one clear line and exit non-zero, without a traceback from inside a library.
"""


class HframeIdError(Exception):
    """Base class of every error that the command line reports as a plain message."""


class ParameterFileError(HframeIdError):
    """A parameter file (models/*.yaml, fits/*.yaml) is missing, malformed or invalid."""


class ModelError(HframeIdError):
    """A model variant, option or signal name does not exist or is invalid."""


class LogFormatError(HframeIdError):
    """An MCAP recording does not follow the hframe-id log format."""


class FitError(HframeIdError):
    """A fit cannot start (bad problem definition) or did not produce a trustworthy result."""


class RigFault(HframeIdError):
    """The rig (simulated or hardware) reported a fault: limit switch, link loss, watchdog."""


class OptionError(HframeIdError):
    """A user-supplied option (command line or options dataclass) is out of range."""
