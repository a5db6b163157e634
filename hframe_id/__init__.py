"""hframe-id: identify, simulate and control belt-driven H-frame XY stages.

The models follow K. S. Sollmann, *Modeling, Simulation and Control of a Belt Driven,
Parallel H-Frame Type Two Axes Positioning System*, M.Sc. thesis, University of Rhode
Island, 2007 (equation and table numbers in docstrings refer to it).
"""


def __getattr__(name: str) -> str:
    """``__version__``, read from the installed package's metadata when first asked for:
    importing importlib.metadata cost 30-64 ms (measured), up to half of ``hframe-id --help``."""
    if name != "__version__":
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from importlib.metadata import PackageNotFoundError, version

    try:
        value = version("hframe-id")
    except PackageNotFoundError:  # running from a source tree that is not installed
        value = "0.0.0+unknown"
    globals()["__version__"] = value
    return value
