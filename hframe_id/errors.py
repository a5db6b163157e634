"""Typed errors raised at the edges of hframe-id.

Every error names what is at fault (file, field, value) so that the command line can print
it as one clear line and exit non-zero, without a traceback from inside a library; values
are echoed through ``shown``, which bounds their length.
"""

import reprlib


class HframeIdError(Exception):
    """Base class of every error that the command line reports as a plain message."""


class ParameterFileError(HframeIdError):
    """A parameter file (models/*.yaml, fits/*.yaml) is missing, malformed or invalid."""


class ModelError(HframeIdError):
    """A model variant, option or signal name does not exist or is invalid."""


class ControllerError(ModelError):
    """A controller file or declaration is missing or invalid, or does not fit the model and
    recording it is run with (docs/custom-models.md, "Your own controller")."""


class LogFormatError(HframeIdError):
    """An MCAP recording does not follow the hframe-id log format."""


class FitError(HframeIdError):
    """A fit cannot start (bad problem definition) or did not produce a trustworthy result."""


class RigFault(HframeIdError):
    """The rig (simulated or hardware) reported a fault: limit switch, link loss, watchdog."""


class OptionError(HframeIdError):
    """A user-supplied option (command line or options dataclass) is out of range."""


class Interrupted(KeyboardInterrupt):
    """The user's Ctrl-C or a SIGTERM, as the command line's signal handler raises it
    (``hframe_id.cli.signals``): told apart from a ``KeyboardInterrupt`` that a model or
    controller file raises itself, which is that file's error."""


#: The most characters of a value an error message shows (``shown``).
MAX_SHOWN = 80


def _bounded_repr() -> reprlib.Repr:
    shortened = reprlib.Repr()
    shortened.maxlevel = 2
    shortened.maxdict = shortened.maxlist = shortened.maxtuple = shortened.maxset = 4
    shortened.maxstring = shortened.maxother = shortened.maxlong = 60
    return shortened


_REPR = _bounded_repr()


def shown(value: object) -> str:
    """A value as an error message shows it: its ``repr``, shortened to at most ``MAX_SHOWN``
    characters (``...`` marks what is left out). The one rule for echoing what a file or a
    user gave: a hostile value (a megabyte string, a YAML alias bomb) is never expanded."""
    text = _REPR.repr(value)
    return text if len(text) <= MAX_SHOWN else text[: MAX_SHOWN - 3] + "..."


#: The most characters of an error message the command line prints (``bounded_message``).
MAX_MESSAGE = 280


def bounded_message(message: object) -> str:
    """A message (an error, a warning) on one line of at most ``MAX_MESSAGE`` characters:
    the safety net behind ``shown`` for a message that echoes a value without it (a
    100 000-column CSV header, a path of 300 characters), so that no input can flood the
    terminal."""
    text = " ".join(str(message).split())
    return text if len(text) <= MAX_MESSAGE else text[: MAX_MESSAGE - 3] + "..."
