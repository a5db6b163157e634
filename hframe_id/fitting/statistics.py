"""Uncertainty and identifiability at the optimum, from the Gauss-Newton information matrix.

At a converged multiple-shooting solution the continuity holds, and the condensed Jacobian
J (rows: weighted residuals; columns: each experiment's initial state, then the free
log-parameters) is the single-shooting Jacobian. From it:

- Fisher information F = J^T J (residuals are in noise units), and the textbook covariance
  s^2 F^-1 with s^2 = 2 cost / (n - n_unknowns).
- A covariance robust to correlated residuals (``"hac"``, the default): the sandwich
  F^-1 Omega F^-1 with Omega = sum over (experiment, channel) blocks of
  sum_{t,s} w(|t - s|) g_t g_s^T, g_t = J_t^T r_t the score of sample t, and w the Bartlett
  (Newey-West) kernel of bandwidth L. Encoder quantization error is not white: while a
  motor creeps or stands it is constant for hundreds of samples, which the textbook formula
  treats as hundreds of independent looks (it understates errors 5-10x). L is chosen per
  block from the residuals: the lag at which their autocorrelation first falls below
  2 / sqrt(n), times ``BANDWIDTH_FACTOR``, within [``MIN_BANDWIDTH``, n / 4].
- Identifiability: the relative standard error of each free parameter (the std of its log),
  and its collinearity index sqrt((C^-1)_ii), C the information about the parameters (initial
  states eliminated) scaled to unit diagonal: how much the other parameters' freedom inflates
  its variance (Brun et al. 2001 use the same normalisation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal
from scipy.stats import norm

#: Bandwidth rule of the HAC estimator (samples): factor on the decorrelation lag, floor.
BANDWIDTH_FACTOR = 2.0
MIN_BANDWIDTH = 10


@dataclass
class Statistics:
    """Covariance and identifiability of the free log-parameters theta."""

    names: tuple[str, ...]
    covariance: np.ndarray  # of theta (relative errors), the chosen method
    covariance_gn: np.ndarray  # textbook Gauss-Newton
    correlation: np.ndarray
    relative_std: np.ndarray
    relative_std_gn: np.ndarray
    collinearity: np.ndarray
    collinearity_set: float
    noise_scale: float  # s: residual std in noise units
    bandwidths: dict[str, int]
    n_residuals: int
    method: str

    def z_value(self, confidence: float) -> float:
        """Two-sided normal quantile of ``confidence`` (1.96 for 95 %)."""
        return float(norm.ppf(0.5 + confidence / 2))


def _bartlett_smooth(g: np.ndarray, bandwidth: int) -> np.ndarray:
    """sum_s w(|t - s|) g_s with w(l) = 1 - l / (L + 1): a triangle, two boxcars convolved."""
    if bandwidth <= 0:
        return g
    box = np.ones((bandwidth + 1, 1))
    once = signal.fftconvolve(g, box, mode="full", axes=0)
    twice = signal.fftconvolve(once, box, mode="full", axes=0)
    n = g.shape[0]
    return twice[bandwidth : bandwidth + n] / (bandwidth + 1)


def decorrelation_lag(r: np.ndarray) -> int:
    """First lag at which the autocorrelation of ``r`` falls below 2 / sqrt(n)."""
    n = r.size
    if n < 4:
        return 0
    x = r - r.mean()
    spectrum = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(spectrum * np.conj(spectrum))[:n]
    if acf[0] <= 0:
        return 0
    acf /= acf[0]
    below = np.flatnonzero(acf < 2 / np.sqrt(n))
    return int(below[0]) if below.size else n


def compute_statistics(
    jac: np.ndarray,
    residual: np.ndarray,
    blocks: list[tuple[str, np.ndarray]],
    n_nuisance: int,
    names: tuple[str, ...],
    method: str,
) -> Statistics:
    """Covariance of the free log-parameters.

    Parameters
    ----------
    jac : (n, n_nuisance + n_theta) Jacobian of the weighted residuals, nuisance (initial
        states) columns first.
    residual : (n,) weighted residuals.
    blocks : (label, row indices in time order) per experiment and channel.
    """
    n, nz = jac.shape
    info = jac.T @ jac
    scale = np.sqrt(np.maximum(np.diag(info), 1e-300))
    info_s = info / np.outer(scale, scale)
    inv_s = np.linalg.pinv(info_s, rcond=1e-13, hermitian=True)
    inv = inv_s / np.outer(scale, scale)
    dof = max(n - nz, 1)
    s2 = float(residual @ residual) / dof
    cov_gn_full = s2 * inv
    bandwidths: dict[str, int] = {}
    omega = np.zeros((nz, nz))
    for label, rows in blocks:
        if rows.size == 0:
            continue
        g = jac[rows] * residual[rows, None]
        lag = decorrelation_lag(residual[rows])
        bandwidth = int(min(max(BANDWIDTH_FACTOR * lag, MIN_BANDWIDTH), rows.size // 4))
        bandwidths[label] = bandwidth
        omega += g.T @ _bartlett_smooth(g, bandwidth)
    omega = 0.5 * (omega + omega.T)
    cov_hac_full = inv @ omega @ inv
    k = slice(n_nuisance, nz)
    cov_gn = cov_gn_full[k, k]
    cov_hac = cov_hac_full[k, k]
    cov = cov_hac if method == "hac" else cov_gn
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    std_gn = np.sqrt(np.maximum(np.diag(cov_gn), 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
    corr = np.nan_to_num(corr)
    # Collinearity: information about theta with the initial states eliminated.
    a = info[:n_nuisance, :n_nuisance]
    b = info[:n_nuisance, k]
    red = info[k, k] - b.T @ np.linalg.lstsq(a, b, rcond=None)[0] if n_nuisance else info[k, k]
    d = np.sqrt(np.maximum(np.diag(red), 1e-300))
    c = red / np.outer(d, d)
    eig = np.linalg.eigvalsh(c)
    collinearity = np.sqrt(np.maximum(np.diag(np.linalg.pinv(c, hermitian=True)), 0.0))
    return Statistics(
        names=names,
        covariance=cov,
        covariance_gn=cov_gn,
        correlation=corr,
        relative_std=std,
        relative_std_gn=std_gn,
        collinearity=collinearity,
        collinearity_set=float(1 / np.sqrt(max(eig[0], 1e-300))),
        noise_scale=float(np.sqrt(s2)),
        bandwidths=bandwidths,
        n_residuals=n,
        method=method,
    )
