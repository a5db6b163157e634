"""Model options: choices that change the equations, not the parameter values."""

from __future__ import annotations

import math
from dataclasses import dataclass

from hframe_id.errors import ModelError

#: Default smoothing velocities of the Coulomb friction F_c * tanh(v / v_s). They are small
#: against the thesis's travel speeds (0.05-0.2 m/s, 5-20 rad/s at the motors), so the
#: smoothed force reaches 99.9 % of F_c within 4 v_s, yet large enough that RK4 at 1 ms needs
#: only O(20) substeps (see hframe_id.simulation.integrators.stable_substeps).
DEFAULT_SMOOTHING_LINEAR_M_PER_S = 1e-3
DEFAULT_SMOOTHING_ANGULAR_RAD_PER_S = 1e-2


@dataclass(frozen=True)
class ModelOptions:
    """Options of the symbolic models.

    Attributes
    ----------
    smoothing_linear_m_per_s : float
        Smoothing velocity v_s [m/s] of the Coulomb force on linear coordinates (x, y, cart).
    smoothing_angular_rad_per_s : float
        Smoothing velocity v_s [rad/s] of the Coulomb torque on pulley angles.
    position_dependent_stiffness : bool
        Use k = AE / l(x, y) (section 4.6, eq. 4.33-4.41) instead of constant belt stiffness.
        Needs the belt-length parameters of the H-frame variants; not available for one-axis.
    """

    smoothing_linear_m_per_s: float = DEFAULT_SMOOTHING_LINEAR_M_PER_S
    smoothing_angular_rad_per_s: float = DEFAULT_SMOOTHING_ANGULAR_RAD_PER_S
    position_dependent_stiffness: bool = False

    def __post_init__(self) -> None:
        for name in ("smoothing_linear_m_per_s", "smoothing_angular_rad_per_s"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ModelError(f"model option {name} must be a positive number, got {value!r}")

    @property
    def smoothing(self) -> tuple[float, float]:
        """(linear [m/s], angular [rad/s]) smoothing velocities, the model's ``s`` input."""
        return (self.smoothing_linear_m_per_s, self.smoothing_angular_rad_per_s)
