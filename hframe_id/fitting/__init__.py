"""Parameter fitting: multiple shooting in CasADi, Gauss-Newton on the lifted problem.

from hframe_id.fitting import FitOptions, fit_recordings
result = fit_recordings(recordings, initial, FitOptions(free=("k_*", "J_M*")))

The names are loaded on first use (PEP 562), so that ``hframe_id.fitting.options`` and
``hframe-id fit --help`` do not import CasADi and SciPy.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from hframe_id.fitting.fit import fit_recordings
    from hframe_id.fitting.gauss_newton_settings import GaussNewtonSettings
    from hframe_id.fitting.options import FitOptions, FitProgress
    from hframe_id.fitting.result import FitResult, ParameterEstimate
    from hframe_id.fitting.strategy_settings import StrategySettings

_HOMES = {
    "FitResult": "hframe_id.fitting.result",
    "ParameterEstimate": "hframe_id.fitting.result",
    "fit_recordings": "hframe_id.fitting.fit",
    "FitOptions": "hframe_id.fitting.options",
    "FitProgress": "hframe_id.fitting.options",
    "GaussNewtonSettings": "hframe_id.fitting.gauss_newton_settings",
    "StrategySettings": "hframe_id.fitting.strategy_settings",
}

__all__ = [
    "FitOptions",
    "FitProgress",
    "FitResult",
    "GaussNewtonSettings",
    "ParameterEstimate",
    "StrategySettings",
    "fit_recordings",
]


def __getattr__(name: str):
    if name not in _HOMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(_HOMES[name]), name)
