"""Reference paths of the end-effector and their motor angles (section 5.2, eq. 5.8-5.12).

Each leg is a straight move with the trapezoidal velocity profile of eq. 5.9: constant
acceleration for T_a = f_a T (eq. 5.8), constant speed v_max, constant deceleration for
T_d = T_a, with the leg time T = d / (v_max (1 - f_a)) (eq. 5.11). The printed eq. 5.9-5.10
write the deceleration branch with t where T - t is meant; here the position on the last branch is
d - (v_max / T_a) (T - t)^2 / 2, which is continuous in position and velocity.

The motors, not the end-effector, are controlled, so a path becomes two motor-angle references
by inverting the rigid kinematics of eq. 1.1 / 5.12,

    [x; y] = r/2 [[-1, 1], [-1, -1]] [phi1; phi2]   <=>   phi1 = -(x + y) / r,  phi2 = (x - y) / r.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hframe_id.errors import OptionError

INCH_M = 0.0254

#: The thesis's test square (section 5.2): legs of 1 in at v_max = 6 in/s with f_a = 0.2.
SQUARE_SIDE_M = 1.0 * INCH_M
SQUARE_V_MAX_M_PER_S = 6.0 * INCH_M
SQUARE_F_A = 0.2

#: Leg order of the test square: +x, +y, -x, -y (counter-clockwise from the origin). Legs 1 and
#: 3 move the bridge (x) and overshoot; legs 2 and 4 move the cart (y) (section 5.4.1: "overshoots
#: when changing from a x-motion to a y-motion"; Fig. 5.11 shows y errors on leg 1). The cart
#: stops short of the leg-2 corner (Table 5.1's undershoot) in either direction; the
#: counter-clockwise offsets of legs 3 and 4 are the closer ones to Table 5.1 (docs/control.md).
SQUARE_DIRECTIONS: tuple[tuple[float, float], ...] = ((1, 0), (0, 1), (-1, 0), (0, -1))


def _positive(name: str, value: float) -> float:
    if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
        raise OptionError(f"{name} must be a positive number, got {value!r}")
    return float(value)


def _nonnegative(name: str, value: float) -> float:
    if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
        raise OptionError(f"{name} must be a number >= 0, got {value!r}")
    return float(value)


def _check_f_a(f_a: float) -> float:
    if not (isinstance(f_a, int | float) and 0 < f_a <= 0.5):
        raise OptionError(
            f"f_a (acceleration time / leg time, eq. 5.8) must be in (0, 0.5], got {f_a!r}"
        )
    return float(f_a)


@dataclass(frozen=True)
class Leg:
    """One straight move with the trapezoidal velocity profile of eq. 5.9.

    Attributes
    ----------
    start_m, end_m : start and end point (x, y) [m].
    v_max_m_per_s : speed of the constant-velocity part [m/s].
    f_a : acceleration (and deceleration) time as a fraction of the leg time (eq. 5.8).
    t_start_s : time the leg starts [s].
    """

    start_m: tuple[float, float]
    end_m: tuple[float, float]
    v_max_m_per_s: float
    f_a: float
    t_start_s: float

    def __post_init__(self) -> None:
        _positive("v_max [m/s]", self.v_max_m_per_s)
        _check_f_a(self.f_a)
        _nonnegative("leg start time [s]", self.t_start_s)
        if not self.distance_m > 0:
            raise OptionError(f"a leg needs distinct start and end points, got {self.start_m}")

    @property
    def distance_m(self) -> float:
        """Length d of the leg [m]."""
        return float(math.dist(self.start_m, self.end_m))

    @property
    def direction(self) -> np.ndarray:
        """Unit vector from start to end."""
        return (np.asarray(self.end_m) - np.asarray(self.start_m)) / self.distance_m

    @property
    def normal(self) -> np.ndarray:
        """Unit normal of the leg, oriented as the thesis's Fig. 5.11 plots the error.

        Positive means above the leg (larger y) for a leg along x, right of it (larger x) for a
        leg along y: ``(-e_y, e_x)`` flipped, if needed, so that its y component (or, for a leg
        along y, its x component) is positive.
        """
        e = self.direction
        n = np.array([-e[1], e[0]])
        if n[1] < -1e-12 or (abs(n[1]) <= 1e-12 and n[0] < 0):
            n = -n
        return n

    @property
    def duration_s(self) -> float:
        """Leg time T = d / (v_max (1 - f_a)) [s] (eq. 5.11)."""
        return self.distance_m / (self.v_max_m_per_s * (1.0 - self.f_a))

    @property
    def accel_time_s(self) -> float:
        """Acceleration (= deceleration) time T_a = f_a T [s] (eq. 5.8)."""
        return self.f_a * self.duration_s

    @property
    def t_end_s(self) -> float:
        """Time the leg ends, t0 + T [s]."""
        return self.t_start_s + self.duration_s

    @property
    def cruise_s(self) -> tuple[float, float]:
        """Start and end time of the constant-velocity part [s]: [t0 + T_a, t0 + T - T_a)."""
        return (self.t_start_s + self.accel_time_s, self.t_end_s - self.accel_time_s)

    def progress(self, t_s: np.ndarray) -> np.ndarray:
        """Distance travelled along the leg at times ``t_s`` [m] (eq. 5.10), clamped to [0, d]."""
        tau = np.clip(np.asarray(t_s, dtype=float) - self.t_start_s, 0.0, self.duration_s)
        big_t, t_a, v = self.duration_s, self.accel_time_s, self.v_max_m_per_s
        a = v / t_a
        return np.where(
            tau < t_a,
            0.5 * a * tau**2,
            np.where(
                tau < big_t - t_a,
                0.5 * v * t_a + v * (tau - t_a),
                self.distance_m - 0.5 * a * (big_t - tau) ** 2,
            ),
        )


@dataclass(frozen=True)
class Trajectory:
    """A path of the end-effector made of legs, then held at the last point.

    Attributes
    ----------
    name : short description (used in reports and plots).
    legs : the legs in time order; between legs (a dwell) the end-effector is held.
    end_time_s : time the reference ends [s] (after the last leg and any settling time).
    """

    name: str
    legs: tuple[Leg, ...]
    end_time_s: float

    def __post_init__(self) -> None:
        if not self.legs:
            raise OptionError("a trajectory needs at least one leg")
        for before, after in zip(self.legs, self.legs[1:], strict=False):
            if after.t_start_s < before.t_end_s - 1e-12:
                raise OptionError("legs of a trajectory must not overlap in time")
            if not np.allclose(before.end_m, after.start_m, atol=1e-12):
                raise OptionError("each leg must start where the previous one ended")
        if self.end_time_s < self.legs[-1].t_end_s - 1e-12:
            raise OptionError("a trajectory must not end before its last leg")

    @property
    def start_m(self) -> tuple[float, float]:
        """Start point (x, y) of the first leg [m]."""
        return self.legs[0].start_m

    def position(self, t_s: np.ndarray) -> np.ndarray:
        """Desired end-effector position (x, y) [m] at times ``t_s``, shape (n, 2)."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        xy = np.tile(np.asarray(self.start_m, dtype=float), (t.size, 1))
        for leg in self.legs:
            started = t >= leg.t_start_s
            xy[started] = np.asarray(leg.start_m) + np.outer(
                leg.progress(t[started]), leg.direction
            )
        return xy

    def sample_times(self, sample_period_s: float) -> np.ndarray:
        """Sample instants k T from 0 to the end of the reference (inclusive) [s]."""
        _positive("sample period [s]", sample_period_s)
        n = int(math.floor(self.end_time_s / sample_period_s + 1e-9)) + 1
        return np.arange(n) * sample_period_s


def square(
    side_m: float = SQUARE_SIDE_M,
    v_max_m_per_s: float = SQUARE_V_MAX_M_PER_S,
    f_a: float = SQUARE_F_A,
    origin_m: tuple[float, float] = (0.0, 0.0),
    settle_s: float = 0.0,
    directions: Sequence[tuple[float, float]] = SQUARE_DIRECTIONS,
) -> Trajectory:
    """The test square of section 5.2: four legs of ``side_m``, back to-back, no dwell.

    The defaults are the thesis's 1 in square at 6 in/s with f_a = 0.2 (T = 0.208 s per leg,
    0.833 s in all); section 5.8 also uses 2 in and 3 in/s. ``settle_s`` holds the last corner
    after the fourth leg (the thesis's runs end with the fourth leg, so its tables report no
    leg-4 overshoot).
    """
    _positive("square side [m]", side_m)
    _nonnegative("settle time [s]", settle_s)
    legs = []
    start = np.asarray(origin_m, dtype=float)
    t = 0.0
    for direction in directions:
        end = start + side_m * np.asarray(direction, dtype=float)
        leg = Leg(tuple(start), tuple(end), v_max_m_per_s, f_a, t)
        legs.append(leg)
        start, t = end, leg.t_end_s
    name = f"square {side_m * 1e3:g} mm at {v_max_m_per_s * 1e3:g} mm/s, f_a = {f_a:g}"
    return Trajectory(name, tuple(legs), t + settle_s)


def point_to_point(
    points_m: Sequence[tuple[float, float]],
    v_max_m_per_s: float = SQUARE_V_MAX_M_PER_S,
    f_a: float = SQUARE_F_A,
    dwell_s: float = 0.0,
    settle_s: float = 0.2,
) -> Trajectory:
    """Straight moves through ``points_m`` (the first is the start), each with eq. 5.9's profile.

    ``dwell_s`` holds each intermediate point before the next move; ``settle_s`` holds the last.
    """
    _nonnegative("dwell time [s]", dwell_s)
    _nonnegative("settle time [s]", settle_s)
    points = [tuple(float(c) for c in p) for p in points_m]
    if len(points) < 2:
        raise OptionError(f"point-to-point needs at least two points, got {len(points)}")
    for p in points:
        if len(p) != 2 or not all(math.isfinite(c) for c in p):
            raise OptionError(f"points must be finite (x, y) pairs [m], got {p!r}")
    legs = []
    t = 0.0
    for a, b in zip(points, points[1:], strict=False):
        leg = Leg(a, b, v_max_m_per_s, f_a, t)
        legs.append(leg)
        t = leg.t_end_s + dwell_s
    end = legs[-1].t_end_s + settle_s
    return Trajectory(f"point-to-point through {len(points)} points", tuple(legs), end)


def motor_angles(xy_m: np.ndarray, r_m: float) -> np.ndarray:
    """Motor angles (phi1, phi2) [rad] of end-effector positions (x, y) [m]: eq. 5.12 inverted."""
    xy = np.atleast_2d(np.asarray(xy_m, dtype=float))
    return np.column_stack([-(xy[:, 0] + xy[:, 1]) / r_m, (xy[:, 0] - xy[:, 1]) / r_m])


def end_effector_from_motor_angles(phi_rad: np.ndarray, r_m: float) -> np.ndarray:
    """End-effector position (x, y) [m] of motor angles by the rigid kinematics of eq. 5.12."""
    phi = np.atleast_2d(np.asarray(phi_rad, dtype=float))
    return 0.5 * r_m * np.column_stack([-phi[:, 0] + phi[:, 1], -phi[:, 0] - phi[:, 1]])


@dataclass(frozen=True)
class Workspace:
    """Reachable rectangle of the end-effector [m], centred on the origin of the H-frame.

    The thesis gives no travel range; the default +/-0.1 m is an assumption (the lasers cover
    about 10 cm, section 1.1; the Chapter 5 paths span at most 2 in). Trajectories that leave the
    workspace are rejected before any simulation.
    """

    x_min_m: float = -0.1
    x_max_m: float = 0.1
    y_min_m: float = -0.1
    y_max_m: float = 0.1

    def __post_init__(self) -> None:
        for name in ("x_min_m", "x_max_m", "y_min_m", "y_max_m"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value)):
                raise OptionError(f"workspace {name} must be a finite number, got {value!r}")
        if not (self.x_min_m < self.x_max_m and self.y_min_m < self.y_max_m):
            raise OptionError(
                f"workspace must have min < max, got x [{self.x_min_m}, {self.x_max_m}], "
                f"y [{self.y_min_m}, {self.y_max_m}]"
            )

    def check(self, trajectory: Trajectory) -> None:
        """Raise ``OptionError`` naming the first point of ``trajectory`` outside the workspace."""
        for i, leg in enumerate(trajectory.legs, start=1):
            for label, (x, y) in (("start", leg.start_m), ("end", leg.end_m)):
                if not (self.x_min_m <= x <= self.x_max_m and self.y_min_m <= y <= self.y_max_m):
                    raise OptionError(
                        f"trajectory leaves the workspace: leg {i} {label} "
                        f"({x:.4g}, {y:.4g}) m is outside x [{self.x_min_m:g}, "
                        f"{self.x_max_m:g}] m, y [{self.y_min_m:g}, {self.y_max_m:g}] m"
                    )
