"""Path metrics per leg, as Tables 5.1-5.9 report them (definitions in docs/control.md).

For leg i with start S_i, end E_i, unit direction e_i, normal n_i (Fig. 5.11's sign: above an
x-leg, right of a y-leg is positive), time window [t0_i, t0_i + T_i] and acceleration time T_a:

overshoot (``overshoot_m``, Tables' "Overshoot at the end of the leg", negative = "Undershoot")
    a(t) = (p(t) - E_i) . e_i is how far the end-effector is past the leg's end along the leg.
    Starting at the deceleration phase (t >= t0_i + T_i - T_a), take the first sample k at which
    the end-effector stops advancing along the leg, a_{k+1} <= a_k, and report a_k: positive if
    it stopped past the corner, negative if it stopped short. Later motion caused by the next
    leg's acceleration (the belt couples the axes) is not part of this leg's overshoot. ``None``
    if the run ends before the end-effector stops (the thesis's "/" for leg 4: its runs end with
    the fourth leg).

maximum offset (``offset_max_m``, Tables' "Offset max")
    d(t) = (p(t) - S_i) . n_i, the distance from the line of the desired leg. The maximum of |d|
    over the constant-velocity part of the leg, t in [t0_i + T_a, t0_i + T_i - T_a): the
    "offset in the steady state motion along the legs" (section 5.4.1), which excludes the
    transient of the previous corner.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hframe_id.control.trajectory import Leg, Trajectory


@dataclass(frozen=True)
class LegMetrics:
    """Deviation of the end-effector from one leg of the desired path [m], times [s]."""

    leg: int
    overshoot_m: float | None
    offset_max_m: float
    overshoot_time_s: float | None
    offset_max_time_s: float


def perpendicular_error(time_s: np.ndarray, xy_m: np.ndarray, trajectory: Trajectory) -> np.ndarray:
    """Signed distance [m] from the line of the leg being driven at each time (Fig. 5.11).

    Before the first leg the first leg counts, between and after legs the last one driven.
    """
    legs = trajectory.legs
    active = np.zeros(time_s.size, dtype=int)
    for i, leg in enumerate(legs):
        active[time_s >= leg.t_start_s - 1e-12] = i
    starts = np.array([leg.start_m for leg in legs])[active]
    normals = np.array([leg.normal for leg in legs])[active]
    return np.einsum("ij,ij->i", xy_m - starts, normals)


def _overshoot(time_s: np.ndarray, xy_m: np.ndarray, leg: Leg) -> tuple[float | None, float | None]:
    along = (xy_m - np.asarray(leg.end_m)) @ leg.direction
    first = int(np.searchsorted(time_s, leg.t_end_s - leg.accel_time_s - 1e-12))
    for k in range(first, time_s.size - 1):
        if along[k + 1] <= along[k]:
            return float(along[k]), float(time_s[k])
    return None, None


def _offset(time_s: np.ndarray, xy_m: np.ndarray, leg: Leg) -> tuple[float, float]:
    begin, end = leg.cruise_s
    window = (time_s >= begin - 1e-12) & (time_s < end - 1e-12)
    if not window.any():
        return 0.0, float(begin)
    distance = np.abs((xy_m[window] - np.asarray(leg.start_m)) @ leg.normal)
    k = int(np.argmax(distance))
    return float(distance[k]), float(time_s[window][k])


def leg_metrics(time_s: np.ndarray, xy_m: np.ndarray, trajectory: Trajectory) -> list[LegMetrics]:
    """Overshoot and maximum offset of every leg (module docstring) from sampled positions."""
    time_s = np.asarray(time_s, dtype=float)
    xy_m = np.asarray(xy_m, dtype=float)
    metrics = []
    for i, leg in enumerate(trajectory.legs, start=1):
        overshoot, t_over = _overshoot(time_s, xy_m, leg)
        offset, t_off = _offset(time_s, xy_m, leg)
        metrics.append(LegMetrics(i, overshoot, offset, t_over, t_off))
    return metrics


def metrics_json(metrics: Sequence[LegMetrics]) -> list[dict]:
    """The ``legs`` list of ``hframe-id control --json``."""
    return [
        {
            "leg": m.leg,
            "overshoot_m": m.overshoot_m,
            "offset_max_m": m.offset_max_m,
            "overshoot_time_s": m.overshoot_time_s,
            "offset_max_time_s": m.offset_max_time_s,
        }
        for m in metrics
    ]
