"""The trust-region subproblems of the Gauss-Newton iterations: min g.d + d.H.d / 2 within
|d|_2 <= radius, for a positive semidefinite H; on a hyperplane n.d = margin (the
stiffness wall's, ``fitting.stiffness_wall``); and within the parameter bounds and a
half-space n.d <= margin, parameters at a bound held (the solver's step)."""

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


def step_on_hyperplane(
    h: np.ndarray, g: np.ndarray, normal: np.ndarray, margin: float, radius: float
) -> tuple[np.ndarray, bool]:
    """argmin g.d + d.H.d / 2 subject to n . d = margin and |d|_2 <= radius: (step, whether
    the trust region left it whole). d = d0 + Z z with d0 the shortest step onto the
    hyperplane and Z an orthonormal basis of its directions; ``trust_region_step`` in z,
    within what the region leaves beyond d0. A hyperplane farther than ``radius``: the step
    towards it, cut at the region. A zero normal constrains nothing."""
    nn = float(normal @ normal)
    if nn == 0.0:
        return trust_region_step(h, g, radius)
    d0 = normal * (margin / nn)
    left = radius**2 - float(d0 @ d0)
    if left <= 0.0:
        return d0 * (radius / math.sqrt(float(d0 @ d0))), False
    # Q of [n, I]: its first column is n's direction, the others span the hyperplane.
    q, _ = np.linalg.qr(np.column_stack([normal, np.eye(len(normal))]))
    z_basis = q[:, 1 : len(normal)]
    z, whole = trust_region_step(z_basis.T @ h @ z_basis, z_basis.T @ (h @ d0 + g), math.sqrt(left))
    return d0 + z_basis @ z, whole


def bounded_step(
    h: np.ndarray,
    g: np.ndarray,
    theta: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    radius: float,
    movable: np.ndarray,
    half_space: tuple[np.ndarray, float] | None = None,
) -> tuple[np.ndarray, bool]:
    """The step from ``theta`` within the trust region, the bounds ``lower``/``upper`` and
    the half-space n . d <= margin (``half_space`` = (n, margin), or None): (step, whether
    the region left it whole).

    Only the ``movable`` parameters move. A parameter at a bound whose step points outward
    is held and the step solved again without it, until none is; the half-space is
    respected on the parameters that move (the minimiser on its hyperplane where the free
    step crosses it, ``step_on_hyperplane``), so that a held parameter does not push the step
    off it. What is left beyond a bound is clipped."""
    sub = movable.copy()
    for _ in range(len(theta) + 1):
        h_sub, g_sub = h[np.ix_(sub, sub)], g[sub]
        d_sub, whole = trust_region_step(h_sub, g_sub, radius)
        if half_space is not None:
            normal, margin = half_space[0][sub], half_space[1]
            if float(normal @ d_sub) > margin:
                d_sub, whole = step_on_hyperplane(h_sub, g_sub, normal, margin, radius)
        d = np.zeros(len(theta))
        d[sub] = d_sub
        out = sub & (((theta <= lower + 1e-12) & (d < 0)) | ((theta >= upper - 1e-12) & (d > 0)))
        if not out.any():
            break
        sub &= ~out
    return np.clip(theta + d, lower, upper) - theta, whole
