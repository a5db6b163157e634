"""Unseen-plants study (issue 25): is an hframe-8 fit right on plants it has never seen?

Each plant is drawn from a wide envelope around the shipped realistic hframe-20 plant
(``draw_plant``, seeded; the dev split is seeds 0..99, the test split 1000..1199 and runs only
with ``--test-split``), or is one of the issue's named plants (``NAMED``). Per plant, as in the
mismatch study (``studies.mismatch``): the six 1 s section-4.4 steps recorded from
the plant (``TRAINING_SETS["steps"]``, sensor seeds 0..5), an hframe-8 fit from Table 4.2 with
the default ``FitOptions()``, then two checks against the plant's own section-4.1 reduction
(``plant.reference()``), both by free-run simulation from each recording's start
(``simulate_channels``):

- training: cost(P) = 0.5 sum_recordings sum_j sum_k (r_jk / sigma_j)^2, sigma_j the fit's
  noise level per channel (``diagnostics.channel_std``); passes if cost(fit) <= 1.05
  cost(reduction): the fit found an optimum at least as good as the truth's (mismatch's
  log-form ``training_criterion`` is reported beside it);
- held-out: the motor-angle (phi1, phi2) residual rms [rad] over the held-out multisine and
  5 V step (``HELD_OUT``, sensor seed 10000); passes if the fit's <= 1.5 x the reduction's.

Each row also says how far the plant's true x or y goes under these protocols
(``plant_travel_m``): a plant past the rig's +/-0.25 m travel would trip the limit switches on
a rig (the summary counts them apart), and past the belt length at the origin (0.35 m) its
position-dependent stiffness blows up: such recordings are not a rig's, and their verdicts
say nothing about the fitter; a travel of 0 m is a plant whose friction holds it still.

A fit that raises is a traceback row (stage, type, message, innermost frame), not a crash; a
worker process that dies is an exit row.

    python -m studies.unseen_plants --named linear lubricated worn heavy --jobs 2
    python -m studies.unseen_plants --seeds 0 1 2 3 4 5 --jobs 2 --json /tmp/dev.json
    python -m studies.unseen_plants --jobs 2                  # the whole dev split (hours)
    python -m studies.unseen_plants --test-split --jobs 2     # the test split: at the end only
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import traceback
from collections.abc import Iterable, Iterator, Mapping
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from hframe_id.atomic import replace_atomically
from hframe_id.errors import OptionError
from hframe_id.fitting import FitOptions, FitResult, fit_recordings
from hframe_id.parameters import ParameterSet, load_parameter_file
from hframe_id.recordings.recording import Recording
from hframe_id.resources import model_file
from hframe_id.rig.plant import Plant
from hframe_id.rig.realistic import SHIPPED_CONSTANTS, record_realistic, run_plant, shipped_plant
from hframe_id.rig.sim import DEFAULT_TRAVEL_M
from hframe_id.validation.replay import simulate_channels
from studies.mismatch import (
    HELD_OUT,
    TABLE_4_2,
    TRAINING_SETS,
    Recorder,
    training_criterion,
    training_recordings,
)
from studies.mismatch_effects import record_smooth

ROOT = Path(__file__).resolve().parents[1]
TABLE_3_1 = model_file("hframe-20-table3.1.yaml")

#: Seeds of the splits: tune on dev, report test once (``--test-split``); the studies up
#: to 2026-11-27 drew their test plants from 1000..1099 (docs/studies/), later ones from
#: 1100..1199.
DEV_SEEDS = range(0, 100)
TEST_SEEDS = range(1000, 1200)

#: Pass thresholds: cost(fit) / cost(reduction) on the training set, and the held-out
#: motor-angle rms of the fit over the reduction's.
TRAINING_RATIO_MAX = 1.05
HELD_OUT_RATIO_MAX = 1.5
#: Channels of the held-out check: the motor angles [rad].
MOTOR_ANGLES = ("phi1", "phi2")
MESSAGE_CHARS = 120
#: The sim rig's limit switches [m]: a plant whose true x or y goes further under the study's
#: protocols would trip them on a rig; ``record_realistic`` has none, and past the belt length
#: at the origin (0.35 m) the position-dependent stiffness k0 l0 / (l0 + dl) blows up.
TRAVEL_M = max(max(abs(low), abs(high)) for low, high in DEFAULT_TRAVEL_M.values())

# The envelope (issue 25). Factors multiply the shipped plant's values.
P_LINEAR = 0.15  # the linear Table 3.1 plant instead of the realistic one
P_NO_COULOMB = 0.15  # Coulomb friction exactly zero
FRICTION_RANGE = (0.01, 10.0)  # log-uniform, one factor for Coulomb, another for viscous
STIFFNESS_RANGE = (0.4, 2.5)  # log-uniform, common to every belt
BELT_VARIATION = 0.10  # per belt, uniform 1 +/- this, on top of the common factor
MASS_RANGE = (0.5, 2.0)  # log-uniform, each mass and inertia on its own
GAIN_RANGE = (0.8, 1.1)  # uniform, g_1 and g_2 [V/V] (absolute values, not factors)
P_NO_CURRENT_LIMIT = 1 / 3
CURRENT_LIMIT_RANGE_A = (6.0, 12.0)  # uniform [A]
MAX_LATENCY_SAMPLES = 3  # actuation delay, encoder and laser latency: 0..3 samples each
P_STICK_SLIP = 0.5  # else "smooth": no Stribeck peak
RATIO_RANGE = (1.0, 1.5)  # uniform static / Coulomb friction of a stick-slip plant
STRIBECK_RANGE = (0.5, 2.0)  # log-uniform factor on both shipped Stribeck velocities

#: hframe-20 parameters by what the envelope does with them (the rest is ``NOT_DRAWN``).
COULOMB = (*(f"tau_c{i}" for i in range(1, 9)), "F_c_cart", "F_c_bridge")
VISCOUS = (*(f"B_{i}" for i in range(1, 9)), "b_cart", "b_bridge")
BELTS = tuple(f"k_{i}" for i in range(1, 10))
MASSES = ("M_cart", "M_bridge", *(f"J_{i}" for i in range(1, 9)))
GAINS = ("g_1", "g_2")


@dataclass(frozen=True)
class PlantDraw:
    """What makes one plant of the study, relative to the shipped realistic hframe-20 plant
    (the defaults are the shipped plant's), or to Table 3.1 for a linear one.

    Attributes
    ----------
    label : how the plant is named in the output (``"seed 3"``, ``"worn"``).
    seed : the seed it was drawn with (None: a named plant).
    linear : the linear Table 3.1 hframe-20 recorded by the plain sim rig (no Coulomb
        friction, current limit, latencies or stick-slip) instead of the realistic plant.
    coulomb, viscous : factors on every Coulomb (tau_c*, F_c_*) and every viscous (B_*,
        b_cart, b_bridge) friction parameter; coulomb 0: no Coulomb friction.
    stiffness, belts : common factor on the belt stiffnesses k_1..k_9, and each belt's own.
    masses : factors on ``MASSES`` (M_cart, M_bridge, J_1..J_8), in that order.
    gains : (g_1, g_2) [V/V]; None: the base plant's.
    current_limit_a : amplifier current limit [A]; None: none.
    latencies : (actuation delay, encoder latency, laser latency) [samples].
    friction : ``"stick-slip"`` (a Stribeck peak) or ``"smooth"`` (none).
    static_to_coulomb_ratio : F_s / F_c [-] (1 for a smooth plant).
    stribeck : factor on both shipped Stribeck velocities.
    """

    label: str
    seed: int | None = None
    linear: bool = False
    coulomb: float = 1.0
    viscous: float = 1.0
    stiffness: float = 1.0
    belts: tuple[float, ...] = (1.0,) * len(BELTS)
    masses: tuple[float, ...] = (1.0,) * len(MASSES)
    gains: tuple[float, float] | None = None
    current_limit_a: float | None = SHIPPED_CONSTANTS.current_limit_a
    latencies: tuple[int, int, int] = (1, 0, 2)
    friction: str = "stick-slip"
    static_to_coulomb_ratio: float = SHIPPED_CONSTANTS.static_to_coulomb_ratio
    stribeck: float = 1.0

    def __post_init__(self) -> None:
        if len(self.belts) != len(BELTS) or len(self.masses) != len(MASSES):
            raise OptionError(
                f"{self.label}: need {len(BELTS)} belt and {len(MASSES)} mass factors, got "
                f"{len(self.belts)} and {len(self.masses)}"
            )
        if self.linear and (
            self.current_limit_a is not None
            or any(self.latencies)
            or self.friction != "smooth"
            or self.gains is not None
            or (self.coulomb, self.viscous) != (1.0, 1.0)
        ):
            raise OptionError(
                f"{self.label}: a linear plant has only stiffness and mass factors (the plain "
                "sim rig records Table 3.1: no current limit, latencies or stick-slip)"
            )

    def describe(self) -> str:
        """The plant's factors on one line (``x``: factor, absolute values with units)."""
        belts = " ".join(f"{b:.2f}" for b in self.belts)
        m_cart, m_bridge, *inertias = self.masses
        shape = (
            f"belts x{self.stiffness:.3g} [{belts}] M_cart x{m_cart:.2f} "
            f"M_bridge x{m_bridge:.2f} J [{' '.join(f'{j:.2f}' for j in inertias)}]"
        )
        if self.linear:
            return f"linear Table 3.1 (plain sim rig): {shape}"
        coulomb = "0" if self.coulomb == 0 else f"x{self.coulomb:.3g}"
        friction = (
            f"stick-slip F_s/F_c {self.static_to_coulomb_ratio:.2f} v_St x{self.stribeck:.2f}"
            if self.friction == "stick-slip"
            else "smooth"
        )
        gains = "as shipped" if self.gains is None else "/".join(f"{g:.3f}" for g in self.gains)
        limit = "none" if self.current_limit_a is None else f"{self.current_limit_a:.1f} A"
        act, enc, laser = self.latencies
        return (
            f"realistic {friction}; Coulomb {coulomb} viscous x{self.viscous:.3g}; {shape}; "
            f"g {gains}; limit {limit}; delays act {act} enc {enc} laser {laser} samples"
        )


def _log_uniform(
    rng: np.random.Generator, bounds: tuple[float, float], size: int | None = None
) -> np.ndarray | float:
    """exp(U(log low, log high)): a factor as likely to halve as to double."""
    return np.exp(rng.uniform(np.log(bounds[0]), np.log(bounds[1]), size))


def draw_plant(seed: int) -> PlantDraw:
    """A plant from the envelope, seeded by ``default_rng(seed)``.

    Every draw is made for every plant, in a fixed order, whatever the branches (linear,
    Coulomb zero, limit off, smooth), so that one branch does not reshuffle the others.
    """
    rng = np.random.default_rng(seed)
    linear = rng.uniform() < P_LINEAR
    no_coulomb = rng.uniform() < P_NO_COULOMB
    coulomb, viscous = _log_uniform(rng, FRICTION_RANGE, 2)
    stiffness = _log_uniform(rng, STIFFNESS_RANGE)
    belts = rng.uniform(1 - BELT_VARIATION, 1 + BELT_VARIATION, len(BELTS))
    masses = _log_uniform(rng, MASS_RANGE, len(MASSES))
    gains = rng.uniform(*GAIN_RANGE, len(GAINS))
    no_limit = rng.uniform() < P_NO_CURRENT_LIMIT
    limit = rng.uniform(*CURRENT_LIMIT_RANGE_A)
    latencies = rng.integers(0, MAX_LATENCY_SAMPLES + 1, 3)
    stick_slip = rng.uniform() < P_STICK_SLIP
    ratio = rng.uniform(*RATIO_RANGE)
    stribeck = _log_uniform(rng, STRIBECK_RANGE)
    common = {
        "label": f"seed {seed}",
        "seed": int(seed),
        "stiffness": float(stiffness),
        "belts": tuple(float(b) for b in belts),
        "masses": tuple(float(m) for m in masses),
    }
    if linear:
        return linear_draw(**common)
    return PlantDraw(
        **common,
        coulomb=0.0 if no_coulomb else float(coulomb),
        viscous=float(viscous),
        gains=(float(gains[0]), float(gains[1])),
        current_limit_a=None if no_limit else float(limit),
        latencies=tuple(int(n) for n in latencies),
        friction="stick-slip" if stick_slip else "smooth",
        static_to_coulomb_ratio=float(ratio) if stick_slip else 1.0,
        stribeck=float(stribeck) if stick_slip else 1.0,
    )


def linear_draw(label: str, **shape) -> PlantDraw:
    """A linear plant (Table 3.1, plain sim rig) with the stiffness / mass factors ``shape``."""
    return PlantDraw(
        label,
        linear=True,
        current_limit_a=None,
        latencies=(0, 0, 0),
        friction="smooth",
        static_to_coulomb_ratio=1.0,
        **shape,
    )


#: The issue's named plants (``--named``).
NAMED = {
    "linear": linear_draw("linear"),
    "lubricated": PlantDraw("lubricated", coulomb=0.03, current_limit_a=None),
    "worn": PlantDraw("worn", stiffness=0.55, coulomb=3.0, viscous=3.0),
    "heavy": PlantDraw(
        "heavy",
        masses=(1.8,) + (1.0,) * (len(MASSES) - 1),
        coulomb=0.5,
        viscous=0.5,
        current_limit_a=12.0,
    ),
}


def linear_base() -> Plant:
    """Table 3.1's linear hframe-20 as a plant: no Coulomb friction (the table's), no current
    limit, no Stribeck peak or latencies, constant belt stiffness (no belt lengths)."""
    return Plant(
        parameters=load_parameter_file(TABLE_3_1, "hframe-20"),
        constants=replace(SHIPPED_CONSTANTS, static_to_coulomb_ratio=1.0, current_limit_a=math.inf),
        title="linear hframe-20 plant (Table 3.1)",
    )


def scaled_values(values: Mapping[str, float], draw: PlantDraw) -> dict[str, float]:
    """``values`` (hframe-20, SI) with the draw's factors applied and its gains set; the
    parameters ``NOT_DRAWN`` by the envelope are kept."""
    factors = {
        **{name: draw.coulomb for name in COULOMB},
        **{name: draw.viscous for name in VISCOUS},
        **{name: draw.stiffness * b for name, b in zip(BELTS, draw.belts, strict=True)},
        **dict(zip(MASSES, draw.masses, strict=True)),
    }
    scaled = {name: value * factors.get(name, 1.0) for name, value in values.items()}
    if draw.gains is not None:
        scaled.update(zip(GAINS, draw.gains, strict=True))
    return scaled


def build_plant(draw: PlantDraw) -> Plant:
    """The plant of ``draw``: the shipped realistic hframe-20 (or Table 3.1's linear one) with
    the draw's factors, friction law, current limit and latencies."""
    base = linear_base() if draw.linear else shipped_plant("hframe-20")
    params = ParameterSet(
        variant="hframe-20",
        values=scaled_values(base.parameters.values, draw),
        title=f"unseen-plants {draw.label}",
        source=f"studies.unseen_plants: {base.parameters.title}, scaled",
        references=list(base.parameters.references),
        notes=draw.describe(),
    )
    c = base.constants
    constants = replace(
        c,
        static_to_coulomb_ratio=draw.static_to_coulomb_ratio,
        stribeck_velocity_linear_m_per_s=c.stribeck_velocity_linear_m_per_s * draw.stribeck,
        stribeck_velocity_angular_rad_per_s=c.stribeck_velocity_angular_rad_per_s * draw.stribeck,
        current_limit_a=math.inf if draw.current_limit_a is None else draw.current_limit_a,
    )
    act, enc, laser = draw.latencies
    return base.with_parameters(
        params,
        constants=constants,
        actuation_delay_samples=act,
        encoder_latency_samples=enc,
        laser_latency_samples=laser,
        title=f"unseen-plants {draw.label}",
        seed=draw.seed,
    )


def recorder_for(draw: PlantDraw) -> Recorder:
    """How the plant is recorded: the plain sim rig for a linear plant, else the realistic one."""
    return record_smooth if draw.linear else record_realistic


def checked_reference(plant: Plant) -> ParameterSet:
    """The plant's section-4.1 reduction to hframe-8; ``ParameterSet`` refuses a value a
    parameter file may not hold (``ParameterFileError``), and a non-finite one here."""
    reference = plant.reference()
    bad = [name for name, value in reference.values.items() if not math.isfinite(value)]
    if bad:
        raise OptionError(f"{plant.title}: reduction not finite in {', '.join(bad)}")
    return reference


def plant_travel_m(plant: Plant, protocols: Iterable, sample_period_s: float = 1e-3) -> float:
    """Largest |x| or |y| [m] of the plant's true motion under ``protocols`` (``run_plant``:
    the recordings' own integration, without sensors); inf if that is not finite."""
    columns = [i for i, s in enumerate(plant.model.outputs) if s.name in ("x", "y")]
    worst = 0.0
    for protocol in protocols:
        outputs = run_plant(plant, protocol.table(sample_period_s)).outputs[:, columns]
        if not np.isfinite(outputs).all():
            return math.inf
        worst = max(worst, float(np.max(np.abs(outputs))))
    return worst


def free_run_residuals(params: ParameterSet, recordings: Iterable[Recording]) -> dict:
    """Per channel name, the free-run simulation residual (measured - simulated) [rad or m]
    over the valid samples of every recording, concatenated; each simulation starts at rest at
    its recording's first measured positions (``simulate_channels``)."""
    parts: dict[str, list[np.ndarray]] = {}
    for recording in recordings:
        data, simulated = simulate_channels(params, recording)
        for j, name in enumerate(data.names):
            valid = data.valid[:, j]
            parts.setdefault(name, []).append(data.measured[valid, j] - simulated[valid, j])
    return {name: np.concatenate(p) for name, p in parts.items()}


def weighted_cost(residuals: Mapping[str, np.ndarray], channel_std: Mapping[str, float]) -> float:
    """0.5 sum_j sum_k (r_jk / sigma_j)^2 [-]: the fit's least-squares cost of free-run
    residuals ``residuals`` (name -> SI) with noise levels ``channel_std`` (name -> SI)."""
    return 0.5 * sum(float(np.sum((r / channel_std[name]) ** 2)) for name, r in residuals.items())


def motor_angle_rms(residuals: Mapping[str, np.ndarray]) -> float:
    """Root mean square [rad] of the motor-angle residuals (``MOTOR_ANGLES``), pooled."""
    pooled = np.concatenate([residuals[name] for name in MOTOR_ANGLES])
    return float(np.sqrt(np.mean(pooled**2)))


def passes_training(cost_fit: float, cost_reduction: float) -> bool:
    """The fit's training cost at most ``TRAINING_RATIO_MAX`` x the reduction's (NaN: no)."""
    return bool(cost_fit <= TRAINING_RATIO_MAX * cost_reduction)


def passes_held_out(rms_fit: float, rms_reduction: float) -> bool:
    """The fit's held-out motor-angle rms at most ``HELD_OUT_RATIO_MAX`` x the reduction's."""
    return bool(rms_fit <= HELD_OUT_RATIO_MAX * rms_reduction)


@dataclass(frozen=True)
class TrialError:
    """An exception a trial raised: where in the trial (``stage``), what, and where in the
    code (the innermost frame, and the innermost frame of this checkout's own code)."""

    stage: str
    type: str
    message: str
    where: str
    where_own: str


def _frame_text(frame: traceback.FrameSummary) -> str:
    """``path:line (function)``, the path relative to the checkout when inside it."""
    path = Path(frame.filename)
    if path.is_relative_to(ROOT):
        path = path.relative_to(ROOT)
    return f"{path}:{frame.lineno} ({frame.name})"


def _is_own(frame: traceback.FrameSummary) -> bool:
    """Whether a frame is in this checkout's code (hframe_id, studies), not in a package."""
    path = Path(frame.filename)
    return path.is_relative_to(ROOT) and not path.is_relative_to(ROOT / ".venv")


def error_of(err: BaseException, stage: str) -> TrialError:
    """The ``TrialError`` of ``err`` raised in ``stage``."""
    frames = traceback.extract_tb(err.__traceback__)
    own = [f for f in frames if _is_own(f)]
    return TrialError(
        stage=stage,
        type=type(err).__name__,
        message=(str(err).splitlines() or [""])[0][:200],
        where=_frame_text(frames[-1]) if frames else "?",
        where_own=_frame_text(own[-1]) if own else "?",
    )


@dataclass
class UnseenTrial:
    """One plant's fit and its two checks; NaN where the trial did not get that far.

    ``cost``, ``criterion`` and ``held_out_rms_rad`` are (fit, reduction) pairs: the
    weighted training cost [-], mismatch's log-form ``training_criterion`` [-] and the held-out
    motor-angle rms [rad].
    """

    draw: PlantDraw
    split: str
    success: bool | None = None
    message: str = ""
    wall_time_s: float = math.nan
    at_bound: tuple[str, ...] = ()
    cost: tuple[float, float] = (math.nan, math.nan)
    criterion: tuple[float, float] = (math.nan, math.nan)
    held_out_rms_rad: tuple[float, float] = (math.nan, math.nan)
    error: TrialError | None = None
    travel_m: float = math.nan  # ``plant_travel_m`` over the training and held-out protocols
    structure: str = ""  # the fit's ``StructureChoice.statement()`` (which model it kept, why)

    @property
    def within_travel(self) -> bool:
        """The plant stays within the rig's travel (``TRAVEL_M``) in every recording; if not,
        its recordings are not a rig's and its verdicts say little about the fitter."""
        return bool(self.travel_m <= TRAVEL_M)

    @property
    def cost_ratio(self) -> float:
        """cost(fit) / cost(reduction) on the training set."""
        return self.cost[0] / self.cost[1] if self.cost[1] > 0 else math.nan

    @property
    def held_out_ratio(self) -> float:
        """Held-out motor-angle rms of the fit over the reduction's."""
        fit, reduction = self.held_out_rms_rad
        return fit / reduction if reduction > 0 else math.nan

    @property
    def passes_training(self) -> bool:
        """``passes_training`` of the costs (False when the trial did not get there)."""
        return passes_training(*self.cost)

    @property
    def passes_held_out(self) -> bool:
        """``passes_held_out`` of the rms values (False when the trial did not get there)."""
        return passes_held_out(*self.held_out_rms_rad)


def split_of(seed: int) -> str:
    """``"dev"``, ``"test"`` or ``"other"``: the split of a seed."""
    return "dev" if seed in DEV_SEEDS else "test" if seed in TEST_SEEDS else "other"


def record_fit(trial: UnseenTrial, result: FitResult, wall_time_s: float) -> None:
    """Copy the fit's outcome into ``trial``."""
    trial.success = bool(result.success)
    trial.message = result.message[:MESSAGE_CHARS]
    trial.wall_time_s = wall_time_s
    trial.at_bound = tuple(name for name, est in result.estimates.items() if est.at_bound)
    choice = result.diagnostics.structure
    trial.structure = choice.statement() if choice else ""


def judge(
    trial: UnseenTrial,
    result: FitResult,
    reference: ParameterSet,
    training: list[Recording],
    held_out: list[Recording],
) -> None:
    """The two checks of the fit against the reduction ``reference``, into ``trial``."""
    std = result.diagnostics.channel_std
    pairs = (result.parameters, reference)
    trial.cost = tuple(weighted_cost(free_run_residuals(p, training), std) for p in pairs)
    trial.criterion = tuple(training_criterion(p, training) for p in pairs)
    trial.held_out_rms_rad = tuple(motor_angle_rms(free_run_residuals(p, held_out)) for p in pairs)


def run_trial(draw: PlantDraw, split: str, noise_seed: int = 0) -> UnseenTrial:
    """Record, fit and judge one plant; an exception becomes ``trial.error`` (its stage, and
    the wall time up to it for a fit that raised)."""
    trial = UnseenTrial(draw=draw, split=split)
    stage, start = "plant", time.perf_counter()
    try:
        plant = build_plant(draw)
        reference = checked_reference(plant)
        record = recorder_for(draw)
        stage = "travel"
        trial.travel_m = plant_travel_m(plant, (*TRAINING_SETS["steps"], *HELD_OUT.values()))
        stage = "training recordings"
        training = training_recordings(plant, noise_seed, "steps", record)
        stage, start = "fit", time.perf_counter()
        result = fit_recordings(training, load_parameter_file(TABLE_4_2), FitOptions())
        record_fit(trial, result, time.perf_counter() - start)
        stage = "held-out recordings"
        held_out = [record(plant, p, 10_000 + noise_seed) for p in HELD_OUT.values()]
        stage = "judging"
        judge(trial, result, reference, training, held_out)
    except Exception as err:  # a study row, not a crash: what raised, and where
        if stage == "fit":
            trial.wall_time_s = time.perf_counter() - start
        trial.error = error_of(err, stage)
    return trial


#: A plant to run: ("seed", 3) or ("named", "worn").
Task = tuple[str, int | str]


def draw_of(task: Task) -> PlantDraw:
    """The plant draw of a task."""
    kind, key = task
    return NAMED[key] if kind == "named" else draw_plant(int(key))


def task_split(task: Task) -> str:
    """``"named"`` for a named plant, else the seed's split (``split_of``)."""
    kind, key = task
    return "named" if kind == "named" else split_of(int(key))


def run_task(task: Task) -> UnseenTrial:
    """``run_trial`` of a task (a worker process's entry point)."""
    return run_trial(draw_of(task), task_split(task))


def exited(task: Task) -> UnseenTrial:
    """The row of a task whose worker process died (a crash in native code, or killed)."""
    return UnseenTrial(
        draw=draw_of(task),
        split=task_split(task),
        error=TrialError("process", "BrokenProcessPool", "the worker process exited", "?", "?"),
    )


def _isolated(task: Task) -> UnseenTrial:
    """``run_task`` in a process of its own: a worker that dies takes only this task."""
    with ProcessPoolExecutor(1) as pool:
        try:
            return pool.submit(run_task, task).result()
        except BrokenProcessPool:
            return exited(task)


def run_tasks(tasks: list[Task], jobs: int) -> Iterator[UnseenTrial]:
    """The trials of ``tasks`` as they finish: in this process for ``jobs`` 1, else in
    ``jobs`` worker processes; tasks a dying worker took down are rerun one at a time."""
    if jobs == 1:
        yield from map(run_task, tasks)
        return
    broken = []
    with ProcessPoolExecutor(jobs) as pool:
        futures = {pool.submit(run_task, task): task for task in tasks}
        for future in as_completed(futures):
            try:
                yield future.result()
            except BrokenProcessPool:
                broken.append(futures[future])
    for task in broken:
        yield _isolated(task)


def _verdict(passed: bool, value: float) -> str:
    """``x1.012 PASS``: a ratio and whether it passed."""
    return f"x{value:.3f} {'PASS' if passed else 'FAIL'}"


def trial_line(t: UnseenTrial) -> str:
    """One plant's result on one line."""
    head = f"{t.draw.label:>10s} {t.split:5s}"
    if not math.isnan(t.travel_m):
        head += f" travel {t.travel_m:.3g} m" + " (LEAVES TRAVEL)" * (not t.within_travel)
    if t.error and t.success is None:
        e = t.error
        return (
            f"{head} {'EXIT' if e.stage == 'process' else 'TRACEBACK'} in {e.stage} "
            f"{t.wall_time_s:6.1f} s: {e.type}: {e.message} at {e.where_own} "
            f"(innermost {e.where})"
        )
    failed = (
        f" TRACEBACK in {t.error.stage}: {t.error.type}: {t.error.message} at {t.error.where_own}"
        if t.error
        else ""
    )
    return (
        f"{head} training {_verdict(t.passes_training, t.cost_ratio)} "
        f"held-out {_verdict(t.passes_held_out, t.held_out_ratio)} "
        f"success={t.success!s:5s} {t.wall_time_s:6.1f} s; log criterion fit/reduction "
        f"{t.criterion[0]:.1f}/{t.criterion[1]:.1f}; phi rms fit/reduction "
        f"{t.held_out_rms_rad[0]:.2e}/{t.held_out_rms_rad[1]:.2e} rad; "
        f"at_bound=[{','.join(t.at_bound)}]{failed}; {t.message}"
        + (f"\n{'':17s}structure: {t.structure}" if t.structure else "")
    )


def summary_lines(trials: list[UnseenTrial]) -> list[str]:
    """Counts of passes, successes, tracebacks and exits, and the fits' wall times."""
    n = len(trials)
    exits = sum(t.error is not None and t.error.stage == "process" for t in trials)
    tracebacks = sum(t.error is not None for t in trials) - exits
    walls = [t.wall_time_s for t in trials if math.isfinite(t.wall_time_s)]
    both = sum(t.passes_training and t.passes_held_out for t in trials)
    lines = [
        f"plants {n}: training criterion pass {sum(t.passes_training for t in trials)}/{n}, "
        f"held-out pass {sum(t.passes_held_out for t in trials)}/{n}, both {both}/{n}; "
        f"success {sum(bool(t.success) for t in trials)}/{n}; tracebacks {tracebacks}, "
        f"exits {exits}",
    ]
    inside = [t for t in trials if t.within_travel]
    lines.append(
        f"within the +/-{TRAVEL_M} m travel {len(inside)}/{n}: training criterion pass "
        f"{sum(t.passes_training for t in inside)}, held-out pass "
        f"{sum(t.passes_held_out for t in inside)}, both "
        f"{sum(t.passes_training and t.passes_held_out for t in inside)}"
    )
    if walls:
        lines.append(
            f"fit wall time: median {float(np.median(walls)):.1f} s, max {max(walls):.1f} s "
            f"({len(walls)} fits)"
        )
    return lines


def strict_json(value):
    """``value`` with NaN / inf as None and tuples as lists: strict JSON."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: strict_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [strict_json(v) for v in value]
    return value


def trial_document(t: UnseenTrial) -> dict:
    """A trial as a JSON-ready dict: its fields, the plant's line and the derived verdicts."""
    return strict_json(
        {
            **asdict(t),
            "plant": t.draw.describe(),
            "cost_ratio": t.cost_ratio,
            "held_out_ratio": t.held_out_ratio,
            "passes_training": t.passes_training,
            "passes_held_out": t.passes_held_out,
            "within_travel": t.within_travel,
        }
    )


def write_json(path: Path, trials: list[UnseenTrial]) -> None:
    """All rows so far and the summary, replacing ``path`` atomically (kept after a crash)."""
    doc = {
        "study": "studies.unseen_plants",
        "thresholds": {"training_ratio": TRAINING_RATIO_MAX, "held_out_ratio": HELD_OUT_RATIO_MAX},
        "summary": summary_lines(trials),
        "rows": [trial_document(t) for t in trials],
    }
    replace_atomically(path, json.dumps(doc, indent=1, allow_nan=False) + "\n")


def whole_count(text: str) -> int:
    """A count option for argparse (``--jobs``, the bench's ``--matched-repeats``): a whole
    number >= 1."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def make_parser() -> argparse.ArgumentParser:
    """The command line (``--help``)."""
    parser = argparse.ArgumentParser(
        prog="python -m studies.unseen_plants",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Without --seeds and --named: the whole dev split (seeds 0..99), or with "
        "--test-split the test split (seeds 1000..1199).",
    )
    parser.add_argument(
        "--seeds", type=int, nargs="+", default=[], help="plants drawn with these seeds"
    )
    parser.add_argument(
        "--named",
        nargs="+",
        choices=tuple(NAMED),
        default=[],
        help="the issue's named plants: linear (Table 3.1, plain sim rig), lubricated "
        "(Coulomb x0.03, no current limit), worn (belts x0.55, friction x3), heavy (M_cart "
        "x1.8, friction x0.5, 12 A limit)",
    )
    parser.add_argument(
        "--test-split",
        action="store_true",
        help="allow seeds 1000..1199 (the test split; look at them once, at the end)",
    )
    parser.add_argument(
        "--jobs",
        type=whole_count,
        default=1,
        help="plants fitted in parallel processes (default 1)",
    )
    parser.add_argument("--json", type=Path, metavar="FILE", help="write every row to FILE")
    return parser


def selected_tasks(args: argparse.Namespace) -> list[Task]:
    """The tasks of the command line, named plants first."""
    seeds = args.seeds
    if not seeds and not args.named:
        seeds = list(TEST_SEEDS if args.test_split else DEV_SEEDS)
    return [("named", n) for n in args.named] + [("seed", s) for s in seeds]


def main(argv: list[str] | None = None) -> int:
    """Run the study; 2 if test-split seeds are asked for without ``--test-split``."""
    args = make_parser().parse_args(argv)
    refused = [s for s in args.seeds if s in TEST_SEEDS]
    if refused and not args.test_split:
        print(
            f"unseen_plants: error: seeds {' '.join(map(str, refused))} are in the test split "
            f"({TEST_SEEDS.start}..{TEST_SEEDS.stop - 1}); add --test-split to run them",
            file=sys.stderr,
        )
        return 2
    tasks = selected_tasks(args)
    print(
        f"unseen plants: {len(tasks)} plant(s), {args.jobs} job(s); training: six 1 s steps, "
        "hframe-8 fit from Table 4.2 with FitOptions(); pass: training cost <= "
        f"{TRAINING_RATIO_MAX} x and held-out phi rms <= {HELD_OUT_RATIO_MAX} x the reduction's",
        flush=True,
    )
    trials: list[UnseenTrial] = []
    for trial in run_tasks(tasks, args.jobs):
        trials.append(trial)
        print(f"{trial_line(trial)}\n{'':17s}plant: {trial.draw.describe()}", flush=True)
        if args.json:
            write_json(args.json, trials)
    for line in summary_lines(trials):
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
