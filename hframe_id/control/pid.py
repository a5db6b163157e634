"""PID control of one motor angle with the thesis's reset-windup logic (section 5.1, Appendix A).

Per sample k (period T, 1 ms on the rig) and motor, with e_k = r_k - y_k the motor-angle error
[rad], the Visual Basic routine of Appendix A computes

    mpd    = K_P e_k + K_D (e_k - e_{k-1}) / T      derivative on the error, e_{-1} = 0
    mpd    = min(max(mpd, U_min), U_max)            P + D clipped to the output range
    itrial = I_{k-1} + K_I e_k T                    trial integral term [V]
    m      = mpd + itrial
    if itrial >= 0:  if m > U_max: I_k = U_max - mpd, m = U_max   else I_k = itrial
    if itrial <  0:  if m < U_min: I_k = U_min - mpd, m = U_min   else I_k = itrial
    u_k    = m

with U_min, U_max = -10 V, +10 V (the D/A converters). The stored integral I is already
multiplied by K_I (it is in volts, Fig. 5.18 plots it). A PD controller is K_I = 0 (section 5.7).

The prose of section 5.1 says more than the code does: that the integral is left untouched when
P + D alone saturates. The code is what ran on the rig and in the Simulink model ("very similar to
the one shown in Appendix A"), so it is what is implemented: when P + D saturates at U_max and
the trial integral is >= 0, the integral is reset to U_max - mpd = 0 (hence "reset windup"); when
the trial integral has the other sign it is accepted and pulls the output off the limit.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import casadi as ca

from hframe_id.errors import OptionError

if TYPE_CHECKING:
    from hframe_id.control.declaration import ControllerDeclaration

#: D/A converter range of the rig [V] (section 1.1).
U_MIN_V = -10.0
U_MAX_V = 10.0
#: Sample period of the rig and of the thesis's closed-loop simulation [s] (section 5.3).
SAMPLE_PERIOD_S = 1e-3


@dataclass(frozen=True)
class PIDGains:
    """Gains of one motor loop: K_P [V/rad], K_I [V/(rad s)], K_D [V s/rad]."""

    kp: float
    ki: float = 0.0
    kd: float = 0.0

    def __post_init__(self) -> None:
        for name in ("kp", "ki", "kd"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise OptionError(f"gain {name} must be a number, got {value!r}")
            if not math.isfinite(value) or value < 0:
                raise OptionError(f"gain {name} must be finite and >= 0, got {value!r}")

    def scaled(self, factor: float) -> PIDGains:
        """All three gains times ``factor`` (section 5.7 raises motor 2's gains by 10 %)."""
        if not (isinstance(factor, int | float) and math.isfinite(factor) and factor > 0):
            raise OptionError(f"gain scale must be a positive number, got {factor!r}")
        return PIDGains(self.kp * factor, self.ki * factor, self.kd * factor)

    def describe(self) -> str:
        """The gains as the thesis's table captions write them, e.g. ``PD K_P = 175, K_D = 4``."""
        kind = "PD" if self.ki == 0 else "PID"
        text = f"{kind} K_P = {self.kp:g}"
        if self.ki:
            text += f", K_I = {self.ki:g}"
        return text + f", K_D = {self.kd:g}"


@dataclass(frozen=True)
class ControllerOptions:
    """Two independent motor-angle loops (Fig. 5.2) with reset-windup PID (Appendix A).

    Attributes
    ----------
    motor1, motor2 : gains of the loops on phi1 and phi2.
    sample_period_s : T [s]; the zero-order holds of Fig. 5.8 sample the angles and hold the
        voltages for one period.
    u_min_v, u_max_v : output limits [V] (the D/A converter range).
    delay_samples : samples between computing a voltage and applying it (0 in Fig. 5.8, where
        the output hold applies u_k from t_k; a rig with a slow link may apply it later).
    """

    motor1: PIDGains
    motor2: PIDGains
    sample_period_s: float = SAMPLE_PERIOD_S
    u_min_v: float = U_MIN_V
    u_max_v: float = U_MAX_V
    delay_samples: int = 0

    def __post_init__(self) -> None:
        for name, value in (("motor1", self.motor1), ("motor2", self.motor2)):
            if not isinstance(value, PIDGains):
                raise OptionError(f"{name} must be PIDGains, got {value!r}")
        t = self.sample_period_s
        if not (isinstance(t, int | float) and math.isfinite(t) and t > 0):
            raise OptionError(f"sample period must be > 0 s, got {t!r}")
        if not (math.isfinite(self.u_min_v) and math.isfinite(self.u_max_v)):
            raise OptionError("output limits must be finite")
        d = self.delay_samples
        if isinstance(d, bool) or not isinstance(d, int) or not 0 <= d <= 100:
            raise OptionError(f"delay_samples must be an integer in 0..100, got {d!r}")
        if not self.u_min_v < 0 < self.u_max_v:
            raise OptionError(
                f"output limits must satisfy u_min < 0 < u_max, got {self.u_min_v}, {self.u_max_v}"
            )

    @classmethod
    def from_gains(
        cls,
        kp: float,
        ki: float,
        kd: float,
        motor2_gain_scale: float = 1.0,
        sample_period_s: float = SAMPLE_PERIOD_S,
    ) -> ControllerOptions:
        """Equal gains on both motors, motor 2's scaled by ``motor2_gain_scale`` (section 5.7)."""
        gains = PIDGains(kp, ki, kd)
        return cls(gains, gains.scaled(motor2_gain_scale), sample_period_s)

    def gain_vector(self) -> list[float]:
        """(K_P1, K_I1, K_D1, K_P2, K_I2, K_D2), the order the closed-loop function takes."""
        return [
            self.motor1.kp, self.motor1.ki, self.motor1.kd,
            self.motor2.kp, self.motor2.ki, self.motor2.kd,
        ]  # fmt: skip

    def with_delay(self, delay_samples: int) -> ControllerOptions:
        """A copy applying each voltage ``delay_samples`` sample periods after it is computed."""
        return replace(self, delay_samples=delay_samples)

    def describe(self) -> str:
        """The gains as the thesis writes them, per motor if the two loops differ (section 5.7)."""
        if self.motor1 == self.motor2:
            return self.motor1.describe()
        return f"motor 1: {self.motor1.describe()}; motor 2: {self.motor2.describe()}"


class ResetWindupPID:
    """Line-by-line port of Appendix A for one motor (the test oracle of the CasADi version).

    ``step(actual, desired)`` returns the output [V]; ``integral`` is the stored K_I-weighted
    integral [V] and ``previous_error`` e_{k-1} [rad].
    """

    def __init__(self, gains: PIDGains, sample_period_s: float = SAMPLE_PERIOD_S,
                 u_min_v: float = U_MIN_V, u_max_v: float = U_MAX_V) -> None:  # fmt: skip
        if not sample_period_s > 0:
            raise OptionError(f"sample period must be > 0 s, got {sample_period_s!r}")
        self.gains = gains
        self.sample_period_s = sample_period_s
        self.u_min_v = u_min_v
        self.u_max_v = u_max_v
        self.integral = 0.0
        self.previous_error = 0.0

    def step(self, actual: float, desired: float) -> float:
        """One sample of the Appendix A routine (module docstring).

        Parameters
        ----------
        actual : measured motor angle y_k [rad].
        desired : reference motor angle r_k [rad].

        Returns
        -------
        float
            Controller output u_k [V], within [u_min_v, u_max_v]; updates ``integral`` and
            ``previous_error``.
        """
        g, t_samp = self.gains, self.sample_period_s
        u_max, u_min = self.u_max_v, self.u_min_v
        err = desired - actual
        mp = g.kp * err
        md = g.kd * (err - self.previous_error) / t_samp
        mpd = mp + md
        if mpd >= u_max:
            mpd = u_max
        elif mpd <= u_min:
            mpd = u_min
        itrial = self.integral + g.ki * err * t_samp
        m = mpd + itrial
        if itrial >= 0:
            if m > u_max:
                self.integral = u_max - mpd
                m = u_max
            else:
                self.integral = itrial
        if itrial < 0:
            if m < u_min:
                self.integral = u_min - mpd
                m = u_min
            else:
                self.integral = itrial
        self.previous_error = err
        return m


def reset_windup_pid(
    error: ca.SX,
    previous_error: ca.SX,
    integral: ca.SX,
    kp: ca.SX,
    ki: ca.SX,
    kd: ca.SX,
    sample_period_s: float,
    u_min: ca.SX,
    u_max: ca.SX,
) -> tuple[ca.SX, ca.SX]:
    """Appendix A as a CasADi expression (``if_else``): returns (output [V], new integral [V])."""
    mpd = kp * error + kd * (error - previous_error) / sample_period_s
    mpd = ca.if_else(mpd >= u_max, u_max, ca.if_else(mpd <= u_min, u_min, mpd))
    itrial = integral + ki * error * sample_period_s
    m = mpd + itrial
    positive = itrial >= 0
    high = m > u_max
    low = m < u_min
    new_integral = ca.if_else(
        positive,
        ca.if_else(high, u_max - mpd, itrial),
        ca.if_else(low, u_min - mpd, itrial),
    )
    output = ca.if_else(positive, ca.if_else(high, u_max, m), ca.if_else(low, u_min, m))
    return output, new_integral


def pid_controller(
    loops: Mapping[str, tuple[str, str]],
    gains: PIDGains | Mapping[str, PIDGains],
    unit: str = "rad",
    sample_period_s: float | None = SAMPLE_PERIOD_S,
    u_min_v: float = U_MIN_V,
    u_max_v: float = U_MAX_V,
    delay_samples: int = 0,
    name: str = "reset-windup-pid",
) -> ControllerDeclaration:
    """The thesis's reset-windup PID (``reset_windup_pid``, Appendix A) as a declared
    controller (``hframe_id.control.declaration``), one loop per command.

    Its gains are K_P, K_I, K_D of every loop in turn, then the output limits u_min, u_max
    (the PID clips its output itself: the reset windup needs them); its memory is every
    loop's previous error, then every loop's integral term. The Chapter 5 loops
    (``closed_loop.closed_loop_step``) are this controller with gains and limits as run-time
    inputs.

    Parameters
    ----------
    loops : command -> (measured output, reference signal), e.g. ``{"u1": ("phi1",
        "phi1_ref"), "u2": ("phi2", "phi2_ref")}`` for the two motor loops of Fig. 5.2.
    gains : one ``PIDGains`` for every loop, or one per command.
    unit : SI unit of the measured outputs and references (``"rad"``: the motor angles); the
        gains are in V per that unit (K_P), per unit second (K_I), V s per unit (K_D).
    sample_period_s : T [s] (default 1 ms, section 5.3); None: the recording's.
    u_min_v, u_max_v : output range [V] (the D/A converters, section 1.1).
    delay_samples : samples between computing a voltage and applying it (0 in Fig. 5.8).
    name : the controller's name.
    """
    from hframe_id.control.declaration import ControllerDeclaration, Gain
    from hframe_id.models.spec import Signal

    per_loop = {c: gains if isinstance(gains, PIDGains) else gains.get(c) for c in loops}
    missing = [c for c, g in per_loop.items() if not isinstance(g, PIDGains)]
    if missing:
        raise OptionError(f"pid_controller: no PIDGains for {', '.join(missing)}")
    declared_gains = [
        Gain(f"{symbol}_{command}", value, gain_unit, f"{symbol} of {command}")
        for command, g in per_loop.items()
        for symbol, value, gain_unit in (
            ("K_P", g.kp, f"V/{unit}"),
            ("K_I", g.ki, f"V/({unit} s)"),
            ("K_D", g.kd, f"V s/{unit}"),
        )
    ]
    declared_gains += [
        Gain("u_min", u_min_v, "V", "lower output limit"),
        Gain("u_max", u_max_v, "V", "upper output limit"),
    ]

    def law(y, r, z, g, sample_period):
        commands, states = {}, {}
        for command, (output, reference) in loops.items():
            error = r[reference] - y[output]
            commands[command], states[f"I_{command}"] = reset_windup_pid(
                error, z[f"e_prev_{command}"], z[f"I_{command}"],
                g[f"K_P_{command}"], g[f"K_I_{command}"], g[f"K_D_{command}"],
                sample_period, g["u_min"], g["u_max"],
            )  # fmt: skip
            states[f"e_prev_{command}"] = error
        return {"commands": commands, "states": states}

    return ControllerDeclaration(
        name=name,
        description="reset-windup PID per motor (thesis, section 5.1 and Appendix A)",
        commands=tuple(
            Signal(c, "V", f"voltage of the loop on {o}") for c, (o, _) in loops.items()
        ),
        measured=tuple(dict.fromkeys(o for o, _ in loops.values())),
        references=tuple(
            Signal(r, unit, f"reference of {o}")
            for r, o in {r: o for o, r in loops.values()}.items()
        ),
        states=tuple(Signal(f"e_prev_{c}", unit, "previous error e_{k-1}") for c in loops)
        + tuple(Signal(f"I_{c}", "V", "stored integral term I_k (K_I-weighted)") for c in loops),
        gains=tuple(declared_gains),
        law=law,
        sample_period_s=sample_period_s,
        delay_samples=delay_samples,
        source="hframe_id.control.pid",
    )
