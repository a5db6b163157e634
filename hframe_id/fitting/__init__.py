"""Parameter fitting: multiple shooting in CasADi, Gauss-Newton on the lifted problem.

from hframe_id.fitting import FitOptions, fit_recordings
result = fit_recordings(recordings, initial, FitOptions(free=("k_*", "J_M*")))
"""

from hframe_id.fitting.fit import FitResult, ParameterEstimate, fit_recordings
from hframe_id.fitting.options import FitOptions, FitProgress

__all__ = ["FitOptions", "FitProgress", "FitResult", "ParameterEstimate", "fit_recordings"]
