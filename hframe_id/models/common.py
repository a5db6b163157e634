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


#: Corner width w [A] of the smooth current limit (``limited_current``). The earlier limit
#: i / (1 + (i / I_max)^20)^(1/20) gave 7.75 A where the realistic plant clips 8.05 A to 8.0 A:
#: 3 % less torque through the whole 6 V H-frame steps
#: (docs/studies/2026-11-24-model-mismatch-hframe-8.md).
CURRENT_LIMIT_WIDTH_A = 0.02

CURRENT_LIMIT = ParameterSpec("I_max", "A", "amplifier current limit (data sheet)")


def _softplus(z: ca.SX) -> ca.SX:
    """w ln(1 + e^(z / w)) [A], w = ``CURRENT_LIMIT_WIDTH_A``, written so that no exponential
    overflows."""
    w = CURRENT_LIMIT_WIDTH_A
    return ca.fmax(z, 0) + w * ca.log1p(ca.exp(-ca.fabs(z) / w))


def limited_current(current: ca.SX, i_max: ca.SX) -> ca.SX:
    """The current i [A] limited smoothly to +/- i_max [A] (odd in i): i - s(i - I_max) +
    s(-i - I_max), a clip with its corners rounded over a few w: i to 1e-20 A up to I_max - 1 A,
    I_max - w ln 2 at i = I_max, I_max to 1e-10 A from I_max + 0.5 A on."""
    return current - _softplus(current - i_max) + _softplus(-current - i_max)


def limited_motor_torque(p: dict[str, ca.SX], voltage: ca.SX, gain: str, rate: ca.SX) -> ca.SX:
    """Motor torque [N m] of a current-limited amplifier: K_t times the current of eq. 2.4,
    (g V - K_e phidot) / R, limited to +/- I_max (``limited_current``)."""
    current = (p[gain] * voltage - p["K_e"] * rate) / p["R"]
    return p["K_t"] * limited_current(current, p["I_max"])


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
