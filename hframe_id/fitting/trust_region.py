"""The trust-region subproblem of the Gauss-Newton iterations: min g.d + d.H.d / 2 within
|d|_2 <= radius, for a positive semidefinite H (the solver's and the stiffness wall's)."""

from __future__ import annotations

import math

import numpy as np


def _norm(v: np.ndarray) -> float:
    """|v|_2, also for finite entries whose squares overflow: ``np.linalg.norm`` (as
    before, bit for bit) where that is finite, else scaled by the largest entry (a gradient
    of 1e200 had a norm of inf, and the region's bisection returned a zero step)."""
    with np.errstate(over="ignore"):
        norm = float(np.linalg.norm(v))
    scale = float(np.max(np.abs(v), initial=0.0))
    if math.isfinite(norm) or not math.isfinite(scale):
        return norm
    return scale * float(np.linalg.norm(v / scale))


def trust_region_step(h: np.ndarray, g: np.ndarray, radius: float) -> tuple[np.ndarray, bool]:
    """argmin g.d + d.H.d / 2 subject to |d|_2 <= radius (More-Sorensen, H = V E V^T >= 0).

    Returns the step and whether it is the full Gauss-Newton step (region inactive).
    """
    if g.size == 0:
        return np.zeros(0), True
    e, v = np.linalg.eigh(h)
    e = np.maximum(e, 1e-14 * max(float(e[-1]), 1e-300))
    gv = v.T @ g

    def step(mu: float) -> np.ndarray:
        return -v @ (gv / (e + mu))

    full = step(0.0)
    if _norm(full) <= radius:
        return full, True
    # |step(mu)| falls with mu and is <= |g| / mu: bisect log(mu) in (|g| / r * 1e-14, |g| / r].
    hi = _norm(g) / radius
    lo = hi * 1e-14
    for _ in range(200):
        product = lo * hi  # the geometric mean, also where the product overflows
        mid = math.sqrt(product) if math.isfinite(product) else math.sqrt(lo) * math.sqrt(hi)
        if _norm(step(mid)) > radius:
            lo = mid
        else:
            hi = mid
        if hi <= lo * (1 + 1e-6):
            break
    return step(hi), False
