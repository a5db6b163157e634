"""Goodness of fit as MATLAB's ``compare`` reports it (normalized root-mean-square error)."""

from __future__ import annotations

import numpy as np


def fit_percent(measured: np.ndarray, predicted: np.ndarray, valid: np.ndarray) -> float:
    """Fit [%] = 100 (1 - ||y - y_hat|| / ||y - mean(y)||) over the valid samples of a channel.

    100 % is a perfect match; 0 % is no better than the measured mean; it is negative for a
    model worse than the mean, and NaN if there are no valid samples or the channel does not
    vary (the normalisation is zero).

    Parameters
    ----------
    measured, predicted : (N,) one channel, in its SI unit (rad, m, rad/s, A, ...).
    valid : (N,) True where the sample counts (measured, predicted both finite).
    """
    use = np.asarray(valid, dtype=bool) & np.isfinite(measured) & np.isfinite(predicted)
    y, y_hat = np.asarray(measured)[use], np.asarray(predicted)[use]
    if y.size == 0:
        return float("nan")
    spread = np.linalg.norm(y - y.mean())
    if spread == 0.0:
        return float("nan")
    return float(100.0 * (1.0 - np.linalg.norm(y - y_hat) / spread))
