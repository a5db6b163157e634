"""The EMPS benchmark's signal processing (Janot et al. 2019), as its MATLAB scripts do it.

Simulation_EMPS.m and Script_IDIM_LS.m compare models with the measured position only after
smoothing and differentiating it; the relative errors of the literature depend on these steps,
so they are reproduced here step for step:

- ``filtered_motion``: q_f = filtfilt(butter(4, 100 Hz / f_nyq), q) (``freq_fil = 5*20.0``,
  ``nfilt = 4``), MATLAB's ``filtfilt`` (odd reflection of 3 (n - 1) = 12 samples at each end,
  n the filter length); dq_f = diffcent(q_f, T), ddq_f = diffcent(dq_f, T) (diffcent.m:
  central differences, one-sided at the two ends), T the recording's sample period.
- ``relative_error_percent``: 100 ||y - y_s|| / ||y|| without the first ``BORDER_SAMPLES``
  (``n_border = 50``: the scripts keep q_f(n_border:N_pts), 1-based; the end is kept).
- ``matlab_decimate``: Script_IDIM_LS.m decimates its observation matrix and the force by
  ``ndecim = round(0.8 f_nyq / (2 x 20 Hz))`` (10 at 1 kHz) with MATLAB's ``decimate``: an
  order-8 Chebyshev type I low-pass (0.05 dB ripple, cut-off 0.8 / r of Nyquist) run forwards
  and backwards, then every r-th sample, ending with the last one.

Checked against the scripts' published numbers on DATA_EMPS.mat (tests/validation/
test_benchmark_scores.py): a least-squares fit on the decimated data gives the published IDIM-LS
estimates to 6 digits and the published 4.08 % force error (SciPy's own ``decimate``, which
keeps every r-th sample from the first, gives 4.14 %).
"""

from __future__ import annotations

import numpy as np


class ScoreUnavailable(Exception):
    """A score cannot be computed on this model and recording; the message says why."""


#: The Butterworth cut-off [Hz]: 5 x the position loop's 20 Hz bandwidth (``freq_fil``).
CUTOFF_HZ = 100.0
#: The Butterworth's order (``nfilt``).
ORDER = 4
#: Samples dropped at the start of every compared signal (``n_border = 50``, 1-based).
BORDER_SAMPLES = 49
#: The bandwidth the decimation keeps: ``freq_decim = 2*20.0`` [Hz].
DECIMATION_BAND_HZ = 40.0
#: MATLAB ``decimate``'s anti-aliasing filter: order, pass-band ripple [dB], cut-off / (f_nyq / r).
DECIMATE_ORDER, DECIMATE_RIPPLE_DB, DECIMATE_CUTOFF = 8, 0.05, 0.8


def _filtfilt(b: np.ndarray, a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """MATLAB's ``filtfilt``: zero phase, odd reflection of 3 (n - 1) samples at each end."""
    from scipy.signal import filtfilt  # 0.3 s to import: only where a score is computed

    return filtfilt(b, a, x, axis=0, padtype="odd", padlen=3 * (max(len(a), len(b)) - 1))


def diffcent(y: np.ndarray, sample_period_s: float) -> np.ndarray:
    """diffcent.m: [y_2 - y_1, (y_3 - y_1) / 2, ..., (y_n - y_{n-2}) / 2, y_n - y_{n-1}] / T,
    along the first axis of ``y``."""
    inner = (y[2:] - y[:-2]) / 2
    return np.concatenate([y[1:2] - y[:1], inner, y[-1:] - y[-2:-1]]) / sample_period_s


def check_length(samples: int, sample_period_s: float) -> None:
    """Raise ``ScoreUnavailable`` unless the record can take the filters and the border."""
    nyquist = 0.5 / sample_period_s
    if CUTOFF_HZ >= nyquist:
        raise ScoreUnavailable(
            f"the benchmark's {CUTOFF_HZ:g} Hz position filter needs a sample rate above "
            f"{2 * CUTOFF_HZ:g} Hz, got {2 * nyquist:g} Hz"
        )
    if samples <= BORDER_SAMPLES + 3 * ORDER:
        raise ScoreUnavailable(
            f"{samples} samples are too few for the benchmark's filters and its "
            f"{BORDER_SAMPLES}-sample border"
        )


def filtered_motion(
    position: np.ndarray, sample_period_s: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(q_f, dq_f, ddq_f): the measured position (N, n) filtered and differentiated twice as
    Simulation_EMPS.m does (module docstring) [unit, unit/s, unit/s^2]."""
    from scipy.signal import butter

    check_length(position.shape[0], sample_period_s)
    b, a = butter(ORDER, CUTOFF_HZ / (0.5 / sample_period_s))
    q_f = _filtfilt(b, a, np.asarray(position, dtype=float))
    dq_f = diffcent(q_f, sample_period_s)
    return q_f, dq_f, diffcent(dq_f, sample_period_s)


def relative_error_percent(
    measured: np.ndarray, simulated: np.ndarray, border: int = BORDER_SAMPLES
) -> float:
    """100 ||y - y_s|| / ||y|| over every sample but the first ``border`` (all columns
    together); NaN where ||y|| is zero."""
    y = np.asarray(measured, dtype=float)[border:]
    y_s = np.asarray(simulated, dtype=float)[border:]
    norm = np.linalg.norm(y)
    return float(100.0 * np.linalg.norm(y - y_s) / norm) if norm > 0 else float("nan")


def decimation_factor(sample_period_s: float) -> int:
    """``ndecim = round(0.8 f_nyq / freq_decim)`` of Script_IDIM_LS.m (10 at 1 kHz), >= 1."""
    return max(1, round(DECIMATE_CUTOFF * (0.5 / sample_period_s) / DECIMATION_BAND_HZ))


def matlab_decimate(x: np.ndarray, factor: int) -> np.ndarray:
    """MATLAB's ``decimate(x, r)`` along the first axis (module docstring); ``x`` itself for
    r = 1."""
    from scipy.signal import cheby1

    if factor == 1:
        return np.asarray(x, dtype=float)
    b, a = cheby1(DECIMATE_ORDER, DECIMATE_RIPPLE_DB, DECIMATE_CUTOFF / factor)
    smoothed = _filtfilt(b, a, np.asarray(x, dtype=float))
    n = smoothed.shape[0]
    first = factor - (factor * -(-n // factor) - n)  # MATLAB's nbeg, 1-based
    return smoothed[first - 1 :: factor]
