"""hframe-id: identify, simulate and control belt-driven H-frame XY stages.

The models follow K. S. Sollmann, *Modeling, Simulation and Control of a Belt Driven,
Parallel H-Frame Type Two Axes Positioning System*, M.Sc. thesis, University of Rhode
Island, 2007 (equation and table numbers in docstrings refer to it).
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("hframe-id")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"
