"""Realistic plants: the shipped ones, fresh seeded ones for studies, and batch recordings.

The shipped plants (``shipped_plant``, written to ``datasets/realistic/plants/``; the values and
why are in docs/realistic-rig.md):

- ``hframe-20``: Table 3.1's stiffness, inertia and motor constants with the Coulomb friction
  Table 3.1 lacks (tau_c1 = tau_c2 = 0.028 N m, tau_c3 = tau_c4 = 0.02 N m on the corner
  pulleys, 0.0015 N m on each bridge pulley, F_c,cart 0.1 N, F_c,bridge 1.9 N), viscous
  friction moved from the linear fit to the Coulomb-plus-viscous split of Table 4.2 (B_i 0.0018
  N m s/rad, b_cart 16.5 N s/m, b_bridge 33.0 N s/m), motor 2's amplifier 5 % weak (g_2 0.95,
  section 5.7) and belt lengths l_3..l_8 = 0.35 m at the origin. Its section-4.1 reduction is
  Table 4.2 within 5 % (stiffness and inertia equal, friction and g_2 not).
- ``one-axis``: Table 2.3 with the idler side drifted (k2 x 0.88, k3 x 0.9, J_2 x 1.1) and
  F_c 0.22 N.

Both with Table 2.2's stick band, breakaway F_s = 1.2 F_c, Stribeck velocities 5 mm/s and
0.25 rad/s (the same belt speed at r = 19.4 mm), stuck coordinates brought to rest in 0.2 ms,
an 8 A current limit, one sample of actuation delay, no encoder latency and two samples of
laser latency.

``realistic_plant(variant, seed)`` draws a fresh plant around the shipped one;
``record_realistic(plant, protocol, seed)`` records it in one batch (no file, no pacing), the
same samples as the ``sim`` rig given the plant (to integration round-off).
"""

from __future__ import annotations

import numpy as np

from hframe_id.errors import OptionError
from hframe_id.parameters import ParameterSet, load_parameter_file
from hframe_id.recordings.recording import Recording
from hframe_id.recordings.sensors import SensorModel, measure_batch, split_outputs
from hframe_id.resources import models_dir
from hframe_id.rig.plant import Plant
from hframe_id.simulation.friction import STICK_BAND_ANGULAR_RAD_PER_S, STICK_BAND_LINEAR_M_PER_S
from hframe_id.simulation.open_loop import SimulationResult
from hframe_id.simulation.realistic import PlantConstants, simulate_realistic

MODELS_DIR = models_dir()
REALISTIC_VARIANTS = ("hframe-20", "one-axis")

#: Effects shared by the shipped plants (docs/realistic-rig.md, "assumed values").
SHIPPED_CONSTANTS = PlantConstants(
    stick_band_linear_m_per_s=STICK_BAND_LINEAR_M_PER_S,
    stick_band_angular_rad_per_s=STICK_BAND_ANGULAR_RAD_PER_S,
    static_to_coulomb_ratio=1.2,
    stribeck_velocity_linear_m_per_s=0.005,
    stribeck_velocity_angular_rad_per_s=0.25,
    current_limit_a=8.0,
    stick_time_constant_s=2e-4,
)
#: Belt section lengths at the origin [m] (section 4.6; docs/realistic-rig.md).
BELT_LENGTHS_M = {f"l_{i}": 0.35 for i in (3, 4, 5, 6, 7, 8)}
_HFRAME_CHANGES = {
    **{f"B_{i}": 0.0018 for i in range(1, 9)},
    "b_cart": 16.5,
    "b_bridge": 33.0,
    "tau_c1": 0.028,
    "tau_c2": 0.028,
    "tau_c3": 0.02,
    "tau_c4": 0.02,
    **{f"tau_c{i}": 0.0015 for i in (5, 6, 7, 8)},
    "F_c_cart": 0.1,
    "F_c_bridge": 1.9,
    "g_2": 0.95,
}
_ONE_AXIS_SCALE = {"k2": 0.88, "k3": 0.9, "J_2": 1.1}
_ONE_AXIS_CHANGES = {"F_c": 0.22}
#: Held when drawing fresh plants: geometry (r, belt lengths) and the datasheet / calibration
#: constants the fitter holds (K_t, K_e, R, g_1); drifting them would be a different study.
NOT_DRAWN = ("r", "K_t", "K_e", "R", "g_1", *BELT_LENGTHS_M)


def _check_variant(variant: str) -> None:
    if variant not in REALISTIC_VARIANTS:
        raise OptionError(
            f"no realistic plant of variant {variant!r}; valid: {', '.join(REALISTIC_VARIANTS)} "
            "(an hframe-8 fit runs on the hframe-20 plant)"
        )


def shipped_plant(variant: str) -> Plant:
    """The plant of ``datasets/realistic/`` for ``"hframe-20"`` or ``"one-axis"``."""
    _check_variant(variant)
    if variant == "hframe-20":
        base = load_parameter_file(MODELS_DIR / "hframe-20-table3.1.yaml")
        values = {**base.values, **_HFRAME_CHANGES, **BELT_LENGTHS_M}
        what = "Table 3.1 with Coulomb friction, Table 4.2's viscous split, g_2 0.95, belts 0.35 m"
    else:
        base = load_parameter_file(MODELS_DIR / "one-axis-table2.3.yaml")
        values = {k: v * _ONE_AXIS_SCALE.get(k, 1.0) for k, v in base.values.items()}
        values.update(_ONE_AXIS_CHANGES)
        what = "Table 2.3 with the idler drifted (k2 x 0.88, k3 x 0.9, J_2 x 1.1), F_c 0.22 N"
    params = ParameterSet(
        variant=variant,
        values=values,
        title=f"realistic {variant} plant: {what}",
        source=f"{base.source}, changed for the realistic sim rig (hframe_id/rig/realistic.py)",
        references=list(base.references),
        notes="Base parameters of datasets/realistic; see docs/realistic-rig.md.",
    )
    return Plant(
        parameters=params,
        constants=SHIPPED_CONSTANTS,
        position_dependent_stiffness=variant == "hframe-20",
        actuation_delay_samples=1,
        encoder_latency_samples=0,
        laser_latency_samples=2,
        title=f"realistic {variant} plant (datasets/realistic)",
        notes="Stick-slip with a Stribeck curve, 8 A current limit, 1 sample actuation delay, "
        "2 samples laser latency"
        + (", belt stiffness k0 l0 / l(x, y)" if variant != "one-axis" else "")
        + ". Generated by 'hframe-id datasets make --realistic'.",
    )


def _factor(rng: np.random.Generator, spread: tuple[float, float]) -> float:
    """1 +/- a uniform draw from ``spread`` (sign drawn too)."""
    sign = 1.0 if rng.uniform() < 0.5 else -1.0
    return 1.0 + sign * rng.uniform(*spread)


def realistic_plant(variant: str, seed: int, spread: tuple[float, float] = (0.10, 0.20)) -> Plant:
    """A fresh realistic plant: the shipped one with each drawn parameter scaled by 1 +/- U(spread).

    Parameters
    ----------
    variant : ``"hframe-20"`` (the plant for hframe-8 fits) or ``"one-axis"``.
    seed : seeds every draw; the same seed gives the same plant, bit for bit.
    spread : (low, high) relative change per parameter (default 10-20 %).

    Every parameter is drawn except ``NOT_DRAWN``; the Stribeck peak (rho - 1) and the
    Stribeck velocities are drawn too; bands, current limit and delays are kept.
    """
    low, high = spread
    if not 0 <= low <= high < 1:
        raise OptionError(f"spread must satisfy 0 <= low <= high < 1, got {spread}")
    base = shipped_plant(variant)
    rng = np.random.default_rng(seed)
    values = {
        name: value if name in NOT_DRAWN else value * _factor(rng, spread)
        for name, value in base.parameters.values.items()
    }
    c = base.constants
    constants = PlantConstants(
        stick_band_linear_m_per_s=c.stick_band_linear_m_per_s,
        stick_band_angular_rad_per_s=c.stick_band_angular_rad_per_s,
        static_to_coulomb_ratio=1.0 + (c.static_to_coulomb_ratio - 1.0) * _factor(rng, spread),
        stribeck_velocity_linear_m_per_s=c.stribeck_velocity_linear_m_per_s * _factor(rng, spread),
        stribeck_velocity_angular_rad_per_s=c.stribeck_velocity_angular_rad_per_s
        * _factor(rng, spread),
        current_limit_a=c.current_limit_a,
        stick_time_constant_s=c.stick_time_constant_s,
    )
    params = ParameterSet(
        variant=variant,
        values=values,
        title=f"realistic {variant} plant, seed {seed}",
        source=f"hframe_id.rig.realistic.realistic_plant({variant!r}, {seed}, {spread})",
        references=list(base.parameters.references),
        notes=f"The shipped realistic plant with each parameter except {', '.join(NOT_DRAWN)} "
        f"scaled by 1 +/- U({low:g}, {high:g}).",
    )
    return base.with_parameters(
        params, constants=constants, seed=int(seed), title=f"realistic {variant} plant, seed {seed}"
    )


def lagged(values: np.ndarray, samples: int, before: np.ndarray | None = None) -> np.ndarray:
    """Rows shifted ``samples`` later; before t_0 ``before`` (default: the first row, rest)."""
    if samples == 0:
        return values
    first = values[:1] if before is None else np.reshape(before, (1, -1))
    return np.vstack([np.repeat(first, samples, axis=0), values[:-samples]])


def run_plant(
    plant: Plant, inputs: np.ndarray, dt: float = 1e-3, n_substeps: int | None = None
) -> SimulationResult:
    """The plant's exact signals for held voltages (``inputs`` (N, n_u) [V], as commanded):
    delayed by the actuation delay, no DAC and no sensors (``hframe-id simulate --plant``)."""
    model = plant.model
    inputs = np.atleast_2d(np.asarray(inputs, dtype=float))
    applied = lagged(inputs, plant.actuation_delay_samples, np.zeros(model.n_inputs))
    n = n_substeps or plant.substeps(dt)
    states = simulate_realistic(model, plant.p, plant.constants, applied, dt, n)
    outputs = np.array(model.output.map(states.shape[0])(states.T)).T.reshape(states.shape[0], -1)
    return SimulationResult(
        time_s=np.arange(states.shape[0]) * dt,
        inputs=inputs,
        states=states,
        outputs=outputs,
        state_labels=tuple(s.label for s in model.states),
        input_labels=tuple(s.label for s in model.inputs),
        output_labels=tuple(s.label for s in model.outputs),
    )


def record_realistic(
    plant: Plant,
    protocol,
    seed: int = 0,
    sample_period_s: float = 1e-3,
    sensors: SensorModel | None = None,
) -> Recording:
    """Record ``protocol`` on ``plant`` in one batch: the sim rig's samples, without a file.

    Parameters
    ----------
    plant : the realistic plant (``Recording.truth`` is its base parameter set; compare an
        hframe-8 fit with ``plant.reference()``).
    protocol : a protocol of ``hframe_id.rig.protocols`` (anything with ``table(period_s)``).
    seed : seeds the encoder power-up phases and the laser noise (as ``SimRig``).
    sample_period_s : sample period [s].
    sensors : sensor models (default: the thesis's rig).
    """
    sensors = sensors or SensorModel()
    model = plant.model
    commanded = np.atleast_2d(protocol.table(sample_period_s))
    if commanded.shape[1] != model.n_inputs:
        raise OptionError(
            f"the protocol drives {commanded.shape[1]} motor(s), the {plant.variant} plant has "
            f"{model.n_inputs}"
        )
    applied = lagged(
        sensors.dac(commanded), plant.actuation_delay_samples, np.zeros(model.n_inputs)
    )
    states = simulate_realistic(
        model, plant.p, plant.constants, applied, sample_period_s, plant.substeps(sample_period_s)
    )[:-1]
    if not np.isfinite(states).all():
        raise OptionError(f"{plant.where()}: the simulation diverged (non-finite states)")
    true_outputs = np.array(model.output.map(states.shape[0])(states.T)).T
    names = tuple(s.name for s in model.outputs)
    encoders, lasers = split_outputs(names)
    seen = true_outputs.copy()
    seen[:, encoders] = lagged(true_outputs, plant.encoder_latency_samples)[:, encoders]
    seen[:, lasers] = lagged(true_outputs, plant.laser_latency_samples)[:, lasers]
    outputs, valid = measure_batch(sensors, names, seen, np.random.default_rng(seed))
    meta = protocol.metadata() if hasattr(protocol, "metadata") else {}
    return Recording(
        variant=plant.variant,
        sample_period_s=sample_period_s,
        time_s=np.arange(commanded.shape[0]) * sample_period_s,
        inputs=commanded,
        input_names=tuple(s.name for s in model.inputs),
        outputs=outputs,
        output_names=names,
        valid=valid,
        rig={"backend": "sim-batch", "seed": seed, "plant": plant.title, **sensors.as_metadata()},
        experiment=dict(meta),
        truth=plant.parameters,
    )
