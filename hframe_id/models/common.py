"""Parameter specs and force laws shared by the model variants."""

from __future__ import annotations

from pathlib import Path

import casadi as ca

from hframe_id.models.spec import ParameterSpec, Signal

RADIUS = ParameterSpec("r", "m", "pulley radius")
#: Parameters every thesis variant holds in a fit by default: geometry and motor constants are
#: measured (data sheet, calipers), not identified; g_1 = 1 fixes the scale between voltage and
#: torque (K_t g / R), which output-error data cannot separate from the inertias otherwise. g_2
#: is free: it absorbs the difference between the two amplifiers (section 4.3).
MEASURED = ("r", "K_t", "K_e", "R", "g_1")
MOTOR_CONSTANTS = (
    ParameterSpec("K_t", "N m/A", "motor torque constant (eq. 2.4)"),
    ParameterSpec("K_e", "V s/rad", "motor back-EMF constant (eq. 2.4)"),
    ParameterSpec("R", "ohm", "motor armature resistance (eq. 2.4)"),
)


def amplifier_gain(motor: int) -> ParameterSpec:
    """Per-motor amplifier gain g_i: volts at the motor per volt commanded (Fig. 2.21)."""
    return ParameterSpec(f"g_{motor}", "V/V", f"amplifier gain of motor {motor}")


def motor_torque(p: dict[str, ca.SX], voltage: ca.SX, gain: str, rate: ca.SX) -> ca.SX:
    """Motor torque [N m], eq. 2.4 / 3.26 with amplifier gain: g K_t/R V - K_t K_e/R phidot."""
    return p[gain] * p["K_t"] / p["R"] * voltage - p["K_t"] * p["K_e"] / p["R"] * rate


def spring_energy(stiffness: ca.SX, stretch: ca.SX) -> ca.SX:
    """Energy [J] of a belt section modelled as a linear spring: 1/2 k stretch^2."""
    return 0.5 * stiffness * stretch**2


def length_scaled_stiffness(
    stiffness: ca.SX, length_at_origin: ca.SX, length_change: ca.SX
) -> ca.SX:
    """Belt stiffness AE / l for a section whose length is l0 + dl (eq. 4.33-4.41).

    ``stiffness`` is the value at the origin, k0 = AE / l0, so k = k0 l0 / (l0 + dl).
    """
    return stiffness * length_at_origin / (length_at_origin + length_change)


HFRAME_INPUTS = (
    Signal("u1", "V", "commanded voltage of motor 1"),
    Signal("u2", "V", "commanded voltage of motor 2"),
)
#: Encoders (motor angles) and lasers (end-effector position), in this order.
HFRAME_OUTPUTS = ("phi1", "phi2", "x", "y")


def thesis_file(name: str) -> Path:
    """A parameter file of the thesis shipped with hframe-id (models/), by file name."""
    from hframe_id.resources import models_dir

    return models_dir() / name
