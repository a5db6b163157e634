"""Closed-loop simulation of the two motor-angle PID loops on an H-frame model (Fig. 5.2, 5.8).

Timing, as in the Simulink diagram of Fig. 5.8 (zero-order holds on both sides of the embedded
PID functions): at t_k = k T the motor angles are sampled, e_k = r_k - phi(t_k) with r_k the
reference (eq. 5.12) at t_k, the reset-windup PID of Appendix A computes u_k, and u_k is held
until t_{k+1}. There is no extra computation delay.

One sample (both PIDs + ``n_substeps`` RK4 steps of the plant) is one CasADi SX function whose
accumulated state is z = [x; e_{k-1} (2); I (2)]: the declared controller's step
(``hframe_id.control.loop.loop_step``) with the two loops of the built-in PID
(``pid.pid_controller``); the horizon is its ``mapaccum``: one call for the whole run,
optionally compiled to native code. Gains and output limits are run-time inputs, so a gain
search reuses the same (compiled) function.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import casadi as ca
import numpy as np

from hframe_id.control.loop import loop_step
from hframe_id.control.pid import ControllerOptions, PIDGains, pid_controller
from hframe_id.control.trajectory import (
    Trajectory,
    Workspace,
    end_effector_from_motor_angles,
    motor_angles,
)
from hframe_id.errors import ModelError, OptionError
from hframe_id.models import Model
from hframe_id.simulation.compiled import evaluate, maybe_compile
from hframe_id.simulation.friction import FrictionOptions
from hframe_id.simulation.open_loop import default_substeps

HFRAME_VARIANTS = ("hframe-8", "hframe-8-current-limit", "hframe-20")
#: The two motor-angle loops of Fig. 5.2 (their gains and limits: the step's run-time inputs).
THESIS_LOOPS = pid_controller(
    {"u1": ("phi1", "phi1_ref"), "u2": ("phi2", "phi2_ref")}, PIDGains(0.0), name="thesis-pid"
)


def check_hframe(model: Model) -> None:
    """The Chapter 5 loops need both motors and the end-effector position."""
    if model.variant not in HFRAME_VARIANTS:
        raise ModelError(
            f"the thesis's PID path needs an H-frame model ({', '.join(HFRAME_VARIANTS)}), "
            f"got a {model.variant} model; run any model under a declared controller with "
            "--controller FILE.py --reference REC.mcap"
        )


@lru_cache(maxsize=16)
def closed_loop_step(
    model: Model,
    n_substeps: int,
    dt: float,
    friction_model: str = "smooth",
    delay_samples: int = 0,
) -> ca.Function:
    """F(z, r, p, s, gains, limits) -> (z_next, u): one sample of both loops and the plant.

    z = [x; e_prev1; e_prev2; I1; I2; u_{k-d} .. u_{k-1}], r = (phi1, phi2) reference [rad],
    gains = (K_P1, K_I1, K_D1, K_P2, K_I2, K_D2), limits = (u_min, u_max) [V]; u is the voltage
    the controller commands at t_k. With ``delay_samples`` d > 0 the plant gets u_{k-d} over
    [t_k, t_{k+1}) (a computation / transport delay; d = 0 in Fig. 5.8).
    """
    check_hframe(model)
    loops = replace(THESIS_LOOPS, delay_samples=delay_samples)
    step = loop_step(model, loops, n_substeps, dt, friction_model)
    z = ca.SX.sym("z", step.size1_in(0))
    r = ca.SX.sym("r", 2)
    p = ca.SX.sym("p", len(model.parameters))
    s = ca.SX.sym("s", 2)
    gains = ca.SX.sym("gains", 6)
    limits = ca.SX.sym("limits", 2)
    z_next, _, _, u = step(z, r, ca.DM.zeros(model.n_inputs), p, s, ca.vertcat(gains, limits))
    return ca.Function(
        "closed_loop_step",
        [z, r, p, s, gains, limits],
        [z_next, u],
        ["z", "r", "p", "s", "gains", "limits"],
        ["z_next", "u"],
    )


@lru_cache(maxsize=32)
def closed_loop_horizon(
    model: Model,
    n_substeps: int,
    dt: float,
    n_samples: int,
    friction_model: str = "smooth",
    compiled: bool = False,
    delay_samples: int = 0,
) -> ca.Function:
    """H(z0, R, p, s, gains, limits) -> (Z, U) over ``n_samples`` samples (one call)."""
    step = closed_loop_step(model, n_substeps, dt, friction_model, delay_samples)
    horizon = step.mapaccum("closed_loop", n_samples)
    symbols = [
        ca.MX.sym(name, step.size1_in(i), n_samples if name == "r" else 1)
        for i, name in enumerate(step.name_in())
    ]
    flat = ca.Function(
        f"closed_loop_{model.variant.replace('-', '_')}_{n_samples}_d{delay_samples}",
        symbols,
        horizon.call(symbols),
        step.name_in(),
        ["z_all", "u_all"],
    )
    return maybe_compile(flat, compiled)


_FIXED_COORDINATES = ("x", "y", "phi1", "phi2")


@lru_cache(maxsize=16)
def _spring_newton(model: Model) -> ca.Function:
    """(q, p) -> (dV/dq_free, d2V/dq_free2) for the coordinates other than x, y, phi1, phi2."""
    n_q = model.n_states // 2
    names = [c.name for c in model.coordinates]
    free = [i for i, name in enumerate(names) if name not in _FIXED_COORDINATES]
    q = ca.SX.sym("q", n_q)
    p = ca.SX.sym("p", len(model.parameters))
    energy = model.energy(ca.vertcat(q, ca.DM.zeros(n_q)), p)[1]
    grad = ca.gradient(energy, q)[free]
    return ca.Function("spring_newton", [q, p], [grad, ca.jacobian(grad, q)[:, free]])


def rest_state(model: Model, p: np.ndarray, xy_m: tuple[float, float]) -> np.ndarray:
    """State at rest with the end-effector at ``xy_m`` and no belt stretched.

    x, y and the motor angles (eq. 5.12) are fixed; the other pulley angles (hframe-20) minimize
    the spring energy (Newton; one step for constant stiffness).
    """
    check_hframe(model)
    p = np.asarray(p, dtype=float)
    r = float(p[model.index("parameter", "r")])
    phi = motor_angles(np.asarray(xy_m, dtype=float), r)[0]
    n_q = model.n_states // 2
    names = [c.name for c in model.coordinates]
    q = np.zeros(n_q)
    for name, value in zip(_FIXED_COORDINATES, (xy_m[0], xy_m[1], phi[0], phi[1]), strict=True):
        q[names.index(name)] = value
    free = [i for i, name in enumerate(names) if name not in _FIXED_COORDINATES]
    if free:
        newton = _spring_newton(model)
        for _ in range(5):
            grad, hessian = (np.array(v) for v in newton(q, p))
            if np.max(np.abs(grad)) < 1e-12:
                break
            q[free] -= np.linalg.solve(hessian, grad.ravel())
    return np.concatenate([q, np.zeros(n_q)])


@dataclass(frozen=True)
class ClosedLoopResult:
    """Signals of one closed-loop run at the sample instants t_k = k T (SI).

    Attributes
    ----------
    time_s : (N + 1,) t_0 .. t_N [s].
    reference_xy_m, reference_phi_rad : (N + 1, 2) desired end-effector position and angles.
    states : (N + 1, n_x) plant states.
    xy_m : (N + 1, 2) end-effector position (x, y) [m] of the plant.
    phi_rad : (N + 1, 2) motor angles [rad].
    voltages_v : (N, 2) controller outputs, held from t_k to t_{k+1} [V].
    integral_v : (N + 1, 2) stored integral terms I (K_I-weighted error integrals) [V].
    trajectory, controller, friction : what was simulated.
    n_substeps : RK4 substeps per sample.
    """

    time_s: np.ndarray
    reference_xy_m: np.ndarray
    reference_phi_rad: np.ndarray
    states: np.ndarray
    xy_m: np.ndarray
    phi_rad: np.ndarray
    voltages_v: np.ndarray
    integral_v: np.ndarray
    trajectory: Trajectory
    controller: ControllerOptions
    friction: FrictionOptions
    n_substeps: int
    r_m: float

    @property
    def motor_error_rad(self) -> np.ndarray:
        """Actual minus desired motor angles [rad] (Fig. 5.13)."""
        return self.phi_rad - self.reference_phi_rad

    @property
    def xy_from_encoders_m(self) -> np.ndarray:
        """End-effector position from the motor angles by rigid kinematics (eq. 5.12, Fig. 5.10)."""
        return end_effector_from_motor_angles(self.phi_rad, self.r_m)


def simulate_closed_loop(
    model: Model,
    p: np.ndarray,
    trajectory: Trajectory,
    controller: ControllerOptions,
    friction: FrictionOptions | None = None,
    workspace: Workspace | None = None,
    n_substeps: int | None = None,
    compiled: bool = False,
) -> ClosedLoopResult:
    """Run the two PID loops of Fig. 5.2 along ``trajectory`` from rest at its start point.

    Parameters
    ----------
    model : an H-frame model (hframe-8 or hframe-20).
    p : parameter vector in ``model.parameters`` order (SI).
    trajectory : desired end-effector path (converted to motor angles by eq. 5.12).
    controller : gains, sample period and output limits.
    friction : friction law of the plant (default: the model's smoothed Coulomb law).
    workspace : reachable rectangle; the trajectory must stay inside (default ``Workspace()``).
    n_substeps : RK4 substeps per sample (default: ``default_substeps``).
    compiled : evaluate native code (cached on disk) instead of CasADi's VM.
    """
    check_hframe(model)
    friction = friction or FrictionOptions()
    (workspace or Workspace()).check(trajectory)
    p = np.asarray(p, dtype=float)
    if p.shape != (len(model.parameters),):
        raise OptionError(f"p needs {len(model.parameters)} values, got shape {p.shape}")
    dt = controller.sample_period_s
    time_s = trajectory.sample_times(dt)
    n_samples = time_s.size - 1
    if n_samples < 1:  # before the substeps: a period of 1e308 s overflowed their count
        raise OptionError(f"trajectory of {trajectory.end_time_s} s is shorter than one sample")
    n = n_substeps or default_substeps(model, p, dt, friction)
    r_m = float(p[model.index("parameter", "r")])
    reference_xy = trajectory.position(time_s)
    reference_phi = motor_angles(reference_xy, r_m)
    x0 = rest_state(model, p, trajectory.start_m)
    z0 = np.concatenate([x0, np.zeros(4 + 2 * controller.delay_samples)])
    horizon = closed_loop_horizon(
        model,
        int(n),
        float(dt),
        n_samples,
        friction.model,
        bool(compiled),
        controller.delay_samples,
    )
    z, u = evaluate(
        horizon,
        [
            z0,
            reference_phi[:-1],
            p,
            np.asarray(friction.shape(model), dtype=float),
            np.asarray(controller.gain_vector(), dtype=float),
            np.array([controller.u_min_v, controller.u_max_v]),
        ],
    )
    z = np.vstack([z0, z])
    states = z[:, : model.n_states]
    index = {name: model.index("state", name) for name in ("x", "y", "phi1", "phi2")}
    return ClosedLoopResult(
        time_s=time_s,
        reference_xy_m=reference_xy,
        reference_phi_rad=reference_phi,
        states=states,
        xy_m=states[:, [index["x"], index["y"]]],
        phi_rad=states[:, [index["phi1"], index["phi2"]]],
        voltages_v=u,
        integral_v=z[:, model.n_states + 2 : model.n_states + 4],
        trajectory=trajectory,
        controller=controller,
        friction=friction,
        n_substeps=int(n),
        r_m=r_m,
    )
