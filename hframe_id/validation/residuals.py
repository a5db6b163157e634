"""Residual analysis as MATLAB's ``resid``: whiteness and independence from the inputs.

For a model that captures the dynamics, the simulation residual e = y - y_hat of a channel is
white noise (the sensor's) and uncorrelated with the inputs. Normalized correlations:

    R_ee(tau) = sum_t e_t e_{t+tau} / sum_t e_t^2,                          tau = 0 .. L
    R_eu(tau) = sum_t e_{t+tau} u_t / sqrt(sum_t e_t^2 sum_t u_t^2),        tau = -L .. L

(e and u centred; positive tau: the residual after the input, i.e. input effects the model
missed). Under the hypothesis (e white, or independent of u) each value at tau != 0 (any tau
for R_eu) is approximately normal with std 1 / sqrt(N), so the 99 % band is +/- 2.58 / sqrt(N).
A channel passes if no more lags lie outside the band than chance allows for a sequence that
meets the hypothesis: the 99th percentile of Binomial(lags, 0.01), so a white residual fails
at most 1 % of the time (e.g. 25 lags: up to 2 outside).

Invalid samples (a laser past its range) are set to zero after centring and N counts the valid
ones: the sums then run over fewer pairs, which only narrows the spread of the estimate, so
the band stays conservative.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Two-sided 99 % quantile of the standard normal (MATLAB's resid band).
Z_99 = 2.5758293035489004
#: Default number of lags (MATLAB's default for resid).
DEFAULT_MAX_LAG = 25


@dataclass(frozen=True)
class CorrelationTest:
    """One correlation sequence and its 99 % test.

    Attributes
    ----------
    lags_samples : lags [samples].
    values : normalized correlation at each lag (1 at lag 0 of an autocorrelation).
    band : half-width of the 99 % band, 2.58 / sqrt(N).
    outside : lags (lag 0 of an autocorrelation excluded) outside the band.
    allowed_outside : how many may be outside by chance (Binomial 99th percentile).
    passes : ``outside <= allowed_outside``; None if the correlation is undefined (a constant
        input or a zero residual).
    """

    lags_samples: np.ndarray
    values: np.ndarray
    band: float
    outside: int
    allowed_outside: int
    passes: bool | None


def band_99(n_samples: int) -> float:
    """Half-width of the 99 % band for N samples under whiteness/independence: 2.58 / sqrt(N)
    (infinite without samples: a channel with no valid sample has no test)."""
    return Z_99 / math.sqrt(n_samples) if n_samples > 0 else math.inf


def allowed_outside(n_lags: int) -> int:
    """Lags a sequence meeting the hypothesis leaves outside the 99 % band in 99 % of cases:
    the 0.99 quantile of Binomial(n_lags, 0.01), the smallest k with P(K <= k) >= 0.99
    (summed in logs, the probabilities by their ratio; ``scipy.stats`` costs 1.5 s to import).
    """
    log_pmf = n_lags * math.log(0.99)  # P(K = 0)
    cumulative = 0.0
    for k in range(n_lags + 1):
        cumulative += math.exp(log_pmf)
        if cumulative >= 0.99:
            return k
        log_pmf += math.log((n_lags - k) / (k + 1) * (0.01 / 0.99)) if k < n_lags else 0.0
    return n_lags


def _centred(signal: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``signal`` less its mean over the ``valid`` samples, 0 elsewhere (all 0 if none is)."""
    mean = signal[valid].mean() if valid.any() else 0.0
    return np.where(valid, signal - mean, 0.0)


def _test(lags: np.ndarray, values: np.ndarray, tested: np.ndarray, n: int) -> CorrelationTest:
    band = band_99(n)
    allowed = allowed_outside(int(tested.sum()))
    if not np.all(np.isfinite(values)):
        return CorrelationTest(lags, values, band, 0, allowed, None)
    outside = int(np.count_nonzero(np.abs(values[tested]) > band))
    return CorrelationTest(lags, values, band, outside, allowed, outside <= allowed)


def _lagged_sum(a: np.ndarray, b: np.ndarray, lag: int) -> float:
    """sum_t a_t b_{t+lag}."""
    if lag >= 0:
        return float(a[: a.size - lag] @ b[lag:])
    return float(a[-lag:] @ b[: b.size + lag])


def autocorrelation(residual: np.ndarray, valid: np.ndarray, max_lag: int) -> CorrelationTest:
    """R_ee(tau) for tau = 0 .. max_lag and its whiteness test (lags 1 .. max_lag).

    Parameters
    ----------
    residual : (N,) residual of one channel [its SI unit].
    valid : (N,) True where the residual is defined.
    max_lag : largest lag L [samples].
    """
    valid = np.asarray(valid, dtype=bool)
    e = _centred(np.asarray(residual, dtype=float), valid)
    lags = np.arange(max_lag + 1)
    energy = float(e @ e)
    with np.errstate(invalid="ignore", divide="ignore"):
        values = np.array([_lagged_sum(e, e, int(k)) for k in lags]) / energy
    return _test(lags, values, lags > 0, int(valid.sum()))


def cross_correlation(
    residual: np.ndarray, valid: np.ndarray, signal: np.ndarray, max_lag: int
) -> CorrelationTest:
    """R_eu(tau) for tau = -max_lag .. max_lag and the independence test (every lag).

    Parameters
    ----------
    residual : (N,) residual of one channel [its SI unit].
    valid : (N,) True where the residual is defined.
    signal : (N,) one input [V].
    max_lag : largest |lag| L [samples].
    """
    valid = np.asarray(valid, dtype=bool)
    e = _centred(np.asarray(residual, dtype=float), valid)
    u = _centred(np.asarray(signal, dtype=float), np.ones(e.shape, dtype=bool))
    lags = np.arange(-max_lag, max_lag + 1)
    scale = np.sqrt(float(e @ e) * float(u @ u))
    with np.errstate(invalid="ignore", divide="ignore"):
        values = np.array([_lagged_sum(u, e, int(k)) for k in lags]) / scale
    return _test(lags, values, np.ones(lags.shape, dtype=bool), int(valid.sum()))
