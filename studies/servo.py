"""Servo study (issue 25): a declared rotor model fitted with default settings to a servo's
step-from-rest records, judged by simulation on held-out records.

The issue's servo ("a rotor driven by commanded torque steps from rest, 20 s records, declared
as a one-coordinate model") is not available; this is a stand-in. ``draw_servo(seed)`` draws a
servo whose rigid-body values (J, B, tau_c, tau_0) differ from the catalogue
(``studies/models/rotor-catalogue.yaml``) by log-uniform factors of 0.5-2, with what a real
servo has and the declared model (``studies/models/rotor.py``) lacks:

- static friction above Coulomb's, falling to it over a Stribeck velocity, and sticking at
  rest (Karnopp: a rotor at rest stays there while the other torques stay below the static
  level), where the model has a smoothed Coulomb law;
- cogging, A sin(n theta + phase), A 2-5 % of the largest step torque, n per revolution;
- a torque-constant error (the torque is k tau_commanded, k 0.96-1.04);
- an input delay of 1-3 samples;
- an incremental encoder of 4096 counts per revolution (quantization).

Each record (``servo_record``) is 20 s at 1 kHz: 0.5 s at rest, then torque steps of 1-2.5 s
(levels 40-100 % of ``TAU_MAX`` either sign, or zero, the rotor coasting) drawn per record.
Records 0-2 train, 3-4 are held out. A record is written as the CSV a servo drive's logger
gives (time [s], commanded torque [N.m], encoder position [counts]) and brought in with
``hframe-id import``, the documented path for a declared model (docs/import.md). Then, as a
new user would, with the default settings and the catalogue as the start::

    hframe-id fit --model-file studies/models/rotor.py \\
        --initial studies/models/rotor-catalogue.yaml train-0.mcap train-1.mcap train-2.mcap
    hframe-id validate --model-file studies/models/rotor.py FIT.yaml train-*.mcap
    hframe-id validate --model-file studies/models/rotor.py FIT.yaml held-*.mcap

and the same with ``--continuity none --shooting-interval 50`` (the issue's workaround).
Printed per servo and settings: exit status, wall time, the fit's verdict, the estimates
against the servo's truth, and validate's simulation fit [%] per record.

    python -m studies.servo --seeds 0 1 2 --work /tmp/servo --json /tmp/servo.json
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from hframe_id.atomic import replace_atomically
from studies.unseen_plants import strict_json

ROOT = Path(__file__).resolve().parents[1]
MODEL_FILE = ROOT / "studies" / "models" / "rotor.py"
CATALOGUE_FILE = ROOT / "studies" / "models" / "rotor-catalogue.yaml"
VARIANT = "rotor"

#: The catalogue's values (SI), as in ``studies/models/rotor-catalogue.yaml`` (a test checks it).
CATALOGUE = {"J": 2.0e-4, "B": 2.0e-4, "tau_c": 5.0e-3, "tau_0": 0.0}
#: The model's angular Coulomb smoothing velocity [rad/s] (``ModelOptions``): tanh(w / V_S).
SMOOTHING_RAD_PER_S = 0.01

SAMPLE_PERIOD_S = 1e-3
RECORD_S = 20.0
PREROLL_S = 0.5  # at rest, zero torque, before the first step
STEP_S = (1.0, 2.5)  # uniform duration of a step [s]
TAU_MAX = 0.03  # largest commanded torque [N m]
STEP_LEVEL = (0.4, 1.0)  # uniform |level| / TAU_MAX of a nonzero step
P_ZERO_STEP = 0.3  # a step to zero torque: the rotor coasts down
SUBSTEPS = 10  # integration substeps per sample (0.1 ms)
TRAINING = (0, 1, 2)  # record indices
HELD_OUT = (3, 4)

# The envelope of the stand-in servo.
VALUE_RANGE = (0.5, 2.0)  # log-uniform factor on each catalogue value (J, B, tau_c)
OFFSET_RANGE = 0.02  # true tau_0 uniform in +/- this x TAU_MAX [N m]
STATIC_RATIO = (1.2, 1.8)  # uniform static / Coulomb friction
STRIBECK_RAD_PER_S = (0.05, 0.5)  # log-uniform Stribeck velocity
COGGING = (0.02, 0.05)  # uniform cogging amplitude / TAU_MAX
COGGING_PERIODS = (6, 8, 10, 12)  # cogging periods per revolution
TORQUE_GAIN = (0.96, 1.04)  # uniform torque-constant error k: torque = k tau_commanded
DELAY_SAMPLES = (1, 3)  # input delay [samples], inclusive
COUNTS_PER_REV = 4096

#: What ``hframe-id import`` is told: the encoder's quantization, one count uniform.
NOISE_STD_COUNTS = 1 / math.sqrt(12)
#: The settings compared: the defaults, and the issue's workaround.
SETTINGS = {
    "default": (),
    "none/50": ("--continuity", "none", "--shooting-interval", "50"),
}
FITTED = ("J", "B", "tau_c", "tau_0")


@dataclass(frozen=True)
class Servo:
    """A servo: the rotor's true values (SI) and the effects the declared model lacks.

    Attributes
    ----------
    J, B, tau_c, tau_0 : inertia [kg m^2], viscous [N m s/rad] and Coulomb [N m] friction,
        offset torque [N m]: the declared model's parameters.
    static_ratio : static / Coulomb friction [-] (1: no Stribeck peak).
    stribeck_rad_per_s : Stribeck velocity [rad/s]: the friction level is
        tau_c + (tau_s - tau_c) exp(-(w / v_St)^2).
    sticks : Karnopp stick-slip at rest (True), or the model's smoothed law tau(w) tanh(w /
        ``SMOOTHING_RAD_PER_S``), which creeps (False).
    cogging_nm, cogging_periods, cogging_phase : cogging torque -A sin(n theta + phase) [N m].
    torque_gain : the torque applied per torque commanded [-].
    delay_samples : the commanded torque acts this many samples late.
    counts_per_rev : encoder resolution (None: the exact angle is measured).
    seed : the seed it was drawn with (None: built by hand).
    """

    J: float
    B: float
    tau_c: float
    tau_0: float = 0.0
    static_ratio: float = 1.0
    stribeck_rad_per_s: float = 0.1
    sticks: bool = False
    cogging_nm: float = 0.0
    cogging_periods: int = 0
    cogging_phase: float = 0.0
    torque_gain: float = 1.0
    delay_samples: int = 0
    counts_per_rev: int | None = None
    seed: int | None = None

    @property
    def values(self) -> dict[str, float]:
        """The declared model's parameters (SI) of this servo: its truth."""
        return {"J": self.J, "B": self.B, "tau_c": self.tau_c, "tau_0": self.tau_0}

    def describe(self) -> str:
        """The servo on one line: values as factors on the catalogue, then its effects."""
        factors = " ".join(
            f"{n} x{getattr(self, n) / CATALOGUE[n]:.2f}" for n in ("J", "B", "tau_c")
        )
        friction = (
            f"stick-slip tau_s/tau_c {self.static_ratio:.2f} "
            f"v_St {self.stribeck_rad_per_s:.3f} rad/s"
            if self.sticks
            else "smooth"
        )
        encoder = "exact" if self.counts_per_rev is None else f"{self.counts_per_rev} counts/rev"
        return (
            f"{factors} tau_0 {self.tau_0 * 1e3:+.2f} mN m; {friction}; cogging "
            f"{self.cogging_nm * 1e3:.2f} mN m x{self.cogging_periods}/rev; torque gain "
            f"{self.torque_gain:.3f}; delay {self.delay_samples} ms; encoder {encoder}"
        )


def _log_uniform(rng: np.random.Generator, bounds: tuple[float, float]) -> float:
    """exp(U(log low, log high)): a factor as likely to halve as to double."""
    return float(np.exp(rng.uniform(np.log(bounds[0]), np.log(bounds[1]))))


def draw_servo(seed: int, value_range: tuple[float, float] = VALUE_RANGE) -> Servo:
    """The stand-in servo of ``seed`` (``default_rng(seed)``, every draw in a fixed order);
    J, B and tau_c are the catalogue's times log-uniform factors in ``value_range``."""
    rng = np.random.default_rng(seed)
    j, b, c = (CATALOGUE[n] * _log_uniform(rng, value_range) for n in ("J", "B", "tau_c"))
    return Servo(
        J=j,
        B=b,
        tau_c=c,
        tau_0=float(rng.uniform(-OFFSET_RANGE, OFFSET_RANGE)) * TAU_MAX,
        static_ratio=float(rng.uniform(*STATIC_RATIO)),
        stribeck_rad_per_s=_log_uniform(rng, STRIBECK_RAD_PER_S),
        sticks=True,
        cogging_nm=float(rng.uniform(*COGGING)) * TAU_MAX,
        cogging_periods=int(rng.choice(COGGING_PERIODS)),
        cogging_phase=float(rng.uniform(0.0, 2 * math.pi)),
        torque_gain=float(rng.uniform(*TORQUE_GAIN)),
        delay_samples=int(rng.integers(DELAY_SAMPLES[0], DELAY_SAMPLES[1] + 1)),
        counts_per_rev=COUNTS_PER_REV,
        seed=int(seed),
    )


def declared(values: dict[str, float]) -> Servo:
    """A servo that is the declared model itself (no unmodelled effect), with ``values``."""
    return Servo(**{n: float(values[n]) for n in FITTED})


def torque_steps(rng: np.random.Generator, n_samples: int, dt: float = SAMPLE_PERIOD_S):
    """(n_samples,) commanded torque [N m]: ``PREROLL_S`` at zero, then steps of ``STEP_S``
    to a level of +/- ``STEP_LEVEL`` x ``TAU_MAX``, or to zero with ``P_ZERO_STEP``."""
    torque = np.zeros(n_samples)
    k = round(PREROLL_S / dt)
    while k < n_samples:
        length = round(rng.uniform(*STEP_S) / dt)
        zero = rng.uniform() < P_ZERO_STEP
        level = rng.choice((-1.0, 1.0)) * rng.uniform(*STEP_LEVEL) * TAU_MAX
        torque[k : k + length] = 0.0 if zero else level
        k += length
    return torque


def simulate_servo(
    servo: Servo,
    torque: np.ndarray,
    dt: float = SAMPLE_PERIOD_S,
    theta0: float = 0.0,
    substeps: int = SUBSTEPS,
) -> tuple[np.ndarray, np.ndarray]:
    """True angle [rad] and speed [rad/s] at each sample of a record that starts at rest at
    ``theta0``; row k of ``torque`` [N m] is held from t_k to t_{k+1} and acts
    ``delay_samples`` later.

    J w' = k tau(t - d) + tau_0 - A sin(n theta + phase) - B w - f(w), integrated by RK4 with
    ``substeps`` steps per sample. Smooth law: f = level(w) tanh(w / v_s), the declared
    model's. Stick-slip: f = level(w) sign(w) with the sign of the step's start; a step in
    which w changes sign ends at rest (the crossing interpolated linearly), and a rotor at
    rest breaks away only when the other torques exceed the static level.
    """
    s = servo
    torque = np.asarray(torque, dtype=float)
    applied = s.torque_gain * np.concatenate((np.zeros(s.delay_samples), torque))[: torque.size]
    h = dt / substeps
    peak = s.tau_c * (s.static_ratio - 1.0)
    v_st2 = s.stribeck_rad_per_s**2
    tau_s = s.tau_c * s.static_ratio
    sin, exp, tanh = math.sin, math.exp, math.tanh

    def other(theta: float, u: float) -> float:  # every torque but friction [N m]
        return u + s.tau_0 - s.cogging_nm * sin(s.cogging_periods * theta + s.cogging_phase)

    def accel(theta: float, w: float, u: float, direction: float) -> float:
        level = s.tau_c + peak * exp(-w * w / v_st2) if peak else s.tau_c
        sign = direction if s.sticks else tanh(w / SMOOTHING_RAD_PER_S)
        return (other(theta, u) - s.B * w - level * sign) / s.J

    theta, w, stuck = theta0, 0.0, s.sticks
    angles, speeds = np.empty(torque.size), np.empty(torque.size)
    for k, u in enumerate(applied.tolist()):
        angles[k], speeds[k] = theta, w
        for _ in range(substeps):
            if stuck:
                drive = other(theta, u)
                if abs(drive) <= tau_s:
                    continue
                stuck, w = False, 0.0
                direction = math.copysign(1.0, drive)
            elif s.sticks:
                direction = math.copysign(1.0, w)
            else:
                direction = 0.0
            a1 = accel(theta, w, u, direction)
            a2 = accel(theta + 0.5 * h * w, w + 0.5 * h * a1, u, direction)
            w2 = w + 0.5 * h * a1
            a3 = accel(theta + 0.5 * h * w2, w + 0.5 * h * a2, u, direction)
            w3 = w + 0.5 * h * a2
            a4 = accel(theta + h * w3, w + h * a3, u, direction)
            w4 = w + h * a3
            w_new = w + h * (a1 + 2 * a2 + 2 * a3 + a4) / 6
            if s.sticks and w_new * direction < 0:
                part = w / (w - w_new) if w != w_new else 0.0
                theta += 0.5 * w * part * h
                w, stuck = 0.0, True
                continue
            theta += h * (w + 2 * w2 + 2 * w3 + w4) / 6
            w = w_new
    return angles, speeds


def encoder_counts(servo: Servo, angles: np.ndarray) -> np.ndarray:
    """An incremental encoder's count [counts] of ``angles`` [rad]: 0 at the first sample,
    whole counts of the true angle (its phase within a count is the first angle's)."""
    if servo.counts_per_rev is None:
        raise ValueError("a servo without an encoder (counts_per_rev None) measures no counts")
    per_rad = servo.counts_per_rev / (2 * math.pi)
    counts = np.floor(angles * per_rad)
    return (counts - counts[0]).astype(np.int64)


@dataclass(frozen=True)
class ServoRecord:
    """One record of a servo: what the drive's logger writes, and the truth behind it."""

    index: int
    time_s: np.ndarray
    torque_nm: np.ndarray  # commanded
    counts: np.ndarray | None  # None: a servo without an encoder
    theta_rad: np.ndarray  # true angle, from the record's start
    theta0_rad: float  # the rotor's absolute angle at the start (the cogging's phase)

    @property
    def measured_rad(self) -> np.ndarray:
        """The encoder's angle [rad] (the true one for a servo without an encoder)."""
        if self.counts is None:
            return self.theta_rad
        return self.counts * (2 * math.pi / COUNTS_PER_REV)


def servo_record(servo: Servo, seed: int, index: int, duration_s: float = RECORD_S) -> ServoRecord:
    """Record ``index`` of the servo drawn with ``seed``: its torque steps and start angle
    from ``default_rng((seed, index))``, the rotor at rest at the start."""
    rng = np.random.default_rng((seed, index))
    n = round(duration_s / SAMPLE_PERIOD_S)
    torque = torque_steps(rng, n)
    theta0 = float(rng.uniform(0.0, 2 * math.pi))
    angles, _ = simulate_servo(servo, torque, theta0=theta0)
    counts = None if servo.counts_per_rev is None else encoder_counts(servo, angles)
    return ServoRecord(
        index=index,
        time_s=np.arange(n) * SAMPLE_PERIOD_S,
        torque_nm=torque,
        counts=counts,
        theta_rad=angles - theta0,
        theta0_rad=theta0,
    )


def write_csv(path: Path, record: ServoRecord) -> None:
    """The record as a drive logger's CSV: ``t`` [s], ``torque_cmd`` [N.m], ``position``
    [counts]."""
    if record.counts is None:
        raise ValueError("write_csv needs an encoder record (counts)")
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(("t", "torque_cmd", "position"))
        for t, u, c in zip(record.time_s, record.torque_nm, record.counts, strict=True):
            writer.writerow((f"{t:.3f}", repr(float(u)), int(c)))


def cli(*args: str) -> list[str]:
    """The ``hframe-id`` command line, run by this interpreter (``python -m hframe_id``)."""
    return [sys.executable, "-m", "hframe_id", *args]


def import_command(csv_path: Path, out: Path, description: str) -> list[str]:
    """``hframe-id import`` of a record's CSV into a recording of the rotor model."""
    return cli(
        "import", str(csv_path),
        "--map", "t=time:s",
        "--map", "torque_cmd=input:N.m:tau",
        "--map", "position=output:counts:theta",
        "--counts-per-rev", str(COUNTS_PER_REV),
        "--noise-std", f"theta={NOISE_STD_COUNTS!r}:counts",
        "--variant", VARIANT,
        "--rig-name", "stand-in servo (studies/servo.py)",
        "--description", description,
        "--out", str(out),
        "--force",
    )  # fmt: skip


def write_recordings(servo: Servo, folder: Path) -> tuple[list[Path], list[Path]]:
    """Every record of ``servo`` as CSV and, imported, MCAP in ``folder``: (training,
    held-out) recordings."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = {}
    for index in (*TRAINING, *HELD_OUT):
        kind = "train" if index in TRAINING else "held"
        record = servo_record(servo, servo.seed, index)
        csv_path = folder / f"{kind}-{index}.csv"
        write_csv(csv_path, record)
        out = folder / f"{kind}-{index}.mcap"
        description = (
            f"stand-in servo seed {servo.seed}, record {index}: torque steps from rest, "
            f"{RECORD_S:g} s at 1 kHz"
        )
        subprocess.run(import_command(csv_path, out, description), check=True, capture_output=True)
        paths[index] = out
    return [paths[i] for i in TRAINING], [paths[i] for i in HELD_OUT]


@dataclass(frozen=True)
class Scores:
    """validate's simulation of one recording by one parameter file: fit [%] and residual rms
    [rad] of theta (NaN where validate gives none)."""

    fit_percent: float
    rms_rad: float


@dataclass
class FitRun:
    """One fit of a servo's training records and validate's verdict on it.

    ``training`` and ``held_out`` are validate's simulation scores of the written parameter
    file per record (the one output theta), ``catalogue_*`` the catalogue's beside it; empty
    where the fit wrote no parameter file.
    """

    seed: int
    settings: str
    command: list[str]
    exit_code: int = -1
    wall_time_s: float = math.nan
    verdict: str = ""
    success: bool | None = None
    message: str = ""
    estimates: dict[str, float] = field(default_factory=dict)
    truth: dict[str, float] = field(default_factory=dict)
    at_bound: list[str] = field(default_factory=list)
    not_identified: list[str] = field(default_factory=list)
    fit_file: str = ""
    training: list[Scores] = field(default_factory=list)
    held_out: list[Scores] = field(default_factory=list)
    catalogue_training: list[Scores] = field(default_factory=list)
    catalogue_held_out: list[Scores] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    stderr_tail: str = ""

    def errors_percent(self) -> dict[str, float]:
        """Estimate / truth - 1 [%] of J, B and tau_c (tau_0, near 0, has no ratio)."""
        return {
            name: 100 * (self.estimates[name] / self.truth[name] - 1)
            for name in ("J", "B", "tau_c")
            if name in self.estimates
        }


def verdict_line(stderr: str) -> str:
    """The fit's verdict from its stderr: the ``success: ...`` or ``FAILED: ...`` summary line
    (or a one-line error), and the first sentence of a ``model mismatch:`` statement."""
    lines = [line.strip() for line in stderr.splitlines() if line.strip()]
    verdict = [line for line in lines if line.startswith(("success:", "FAILED:", "hframe-id: "))]
    verdict = [line for line in verdict if "warning" not in line] or lines[-1:]
    mismatch = [line.split(". ")[0] for line in lines if line.startswith("model mismatch:")]
    return " | ".join(verdict + mismatch)


def _number(value) -> float:
    """A JSON number, null as NaN."""
    return math.nan if value is None else float(value)


def simulation_scores(document: dict) -> list[list[Scores]]:
    """theta's ``Scores`` in a validate JSON document: per parameter file, per recording."""
    scores: list[list[Scores]] = [[] for _ in document["parameter_files"]]
    for recording in document["recordings"]:
        for i, result in enumerate(recording["results"]):
            theta = next(c for c in result["channels"] if c["name"] == "theta")
            scores[i].append(
                Scores(_number(theta["simulation_fit_percent"]), _number(theta["residual_rms"]))
            )
    return scores


def validate_scores(fit_file: Path, recordings: Sequence[Path]) -> list[list[Scores]]:
    """``hframe-id validate --json`` of ``fit_file`` and, beside it, the catalogue: per
    parameter file (the fit, the catalogue), per recording, theta's ``Scores``. The
    prediction is skipped (``--horizon 0``): it does not change the simulation fit."""
    done = subprocess.run(
        cli("validate", "--model-file", str(MODEL_FILE), "--horizon", "0", "--json",
            "--params", str(CATALOGUE_FILE), str(fit_file), *map(str, recordings)),
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    return simulation_scores(json.loads(done.stdout))


def run_fit(servo: Servo, settings: str, training, held_out, out_dir: Path) -> FitRun:
    """Fit the training records with ``settings`` (``SETTINGS``), then validate the written
    parameter file on the training and held-out records."""
    command = cli(
        "fit", "--model-file", str(MODEL_FILE), "--initial", str(CATALOGUE_FILE),
        "--out-dir", str(out_dir), "--json", *SETTINGS[settings], *map(str, training),
    )  # fmt: skip
    run = FitRun(seed=servo.seed, settings=settings, command=command, truth=servo.values)
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    run.wall_time_s = time.perf_counter() - start
    run.exit_code = done.returncode
    run.verdict = verdict_line(done.stderr)
    run.warnings = [line.strip() for line in done.stderr.splitlines() if "warning:" in line]
    run.stderr_tail = "\n".join(done.stderr.splitlines()[-15:])
    try:
        document = json.loads(done.stdout)
    except json.JSONDecodeError:  # bad input or a traceback: no JSON object
        return run
    run.success = bool(document["success"])
    run.message = str(document["message"])
    parameters = document["parameters"]
    run.estimates = {n: float(parameters[n]["value"]) for n in FITTED}
    run.at_bound = [n for n in FITTED if parameters[n]["at_bound"]]
    run.not_identified = [n for n in FITTED if not parameters[n]["identified"]]
    if document["parameter_file"]:
        run.fit_file = str(document["parameter_file"])
        run.training, run.catalogue_training = validate_scores(Path(run.fit_file), training)
        run.held_out, run.catalogue_held_out = validate_scores(Path(run.fit_file), held_out)
    return run


def _fits(scores: Sequence[Scores]) -> str:
    return " ".join(f"{x.fit_percent:.1f}" for x in scores)


def run_line(run: FitRun) -> str:
    """One fit on one line."""
    estimates = " ".join(
        f"{n} {run.estimates[n]:.3g} ({e:+.0f} %)" for n, e in run.errors_percent().items()
    )
    if "tau_0" in run.estimates:
        estimates += (
            f" tau_0 {run.estimates['tau_0'] * 1e3:+.2f} mN m "
            f"(true {run.truth['tau_0'] * 1e3:+.2f})"
        )
    flags = "".join(
        f" {label}=[{','.join(names)}]"
        for label, names in (("at_bound", run.at_bound), ("not_identified", run.not_identified))
        if names
    )
    rms = " ".join(f"{x.rms_rad:.3g}" for x in (*run.training, *run.held_out))
    return (
        f"seed {run.seed} {run.settings:8s} exit {run.exit_code} {run.wall_time_s:6.1f} s "
        f"success={run.success}{flags}; {estimates}; fit % training [{_fits(run.training)}] "
        f"held-out [{_fits(run.held_out)}] (rms {rms} rad; catalogue's fit % training "
        f"[{_fits(run.catalogue_training)}] held-out [{_fits(run.catalogue_held_out)}]); "
        f"{run.verdict}"
    )


def write_json(
    path: Path, servos: dict[int, Servo], runs: list[FitRun], value_range: tuple[float, float]
) -> None:
    """Every run so far, with its servo, replacing ``path`` atomically."""
    doc = {
        "study": "studies.servo",
        "value_range": list(value_range),
        "servos": {str(s): {**asdict(v), "describe": v.describe()} for s, v in servos.items()},
        "runs": [{**asdict(r), "errors_percent": r.errors_percent()} for r in runs],
    }
    replace_atomically(path, json.dumps(strict_json(doc), indent=1, allow_nan=False) + "\n")


def make_parser() -> argparse.ArgumentParser:
    """The command line (``--help``)."""
    parser = argparse.ArgumentParser(
        prog="python -m studies.servo",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="servos")
    parser.add_argument(
        "--settings",
        nargs="+",
        choices=tuple(SETTINGS),
        default=list(SETTINGS),
        help="fit settings: the defaults, and --continuity none --shooting-interval 50",
    )
    parser.add_argument(
        "--work", type=Path, required=True, help="folder for the records (CSV, MCAP) and fits"
    )
    parser.add_argument(
        "--value-range",
        type=float,
        nargs=2,
        metavar=("LOW", "HIGH"),
        default=VALUE_RANGE,
        help="J, B and tau_c are the catalogue's times log-uniform factors in [LOW, HIGH] "
        f"(default {VALUE_RANGE[0]:g} {VALUE_RANGE[1]:g})",
    )
    parser.add_argument("--json", type=Path, metavar="FILE", help="write every run to FILE")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the study, one fit at a time."""
    parser = make_parser()
    args = parser.parse_args(argv)
    low, high = args.value_range
    if not 0 < low <= high:
        parser.error(f"--value-range needs 0 < LOW <= HIGH, got {low:g} {high:g}")
    servos, runs = {}, []
    for seed in args.seeds:
        servo = draw_servo(seed, (low, high))
        servos[seed] = servo
        print(f"servo {seed}: {servo.describe()}", flush=True)
        folder = args.work / f"seed-{seed}"
        training, held_out = write_recordings(servo, folder)
        for settings in args.settings:
            out_dir = folder / f"fits-{settings.replace('/', '-')}"
            run = run_fit(servo, settings, training, held_out, out_dir)
            runs.append(run)
            print(run_line(run), flush=True)
            if run.exit_code not in (0, 1):
                print(run.stderr_tail, flush=True)
            if args.json:
                write_json(args.json, servos, runs, (low, high))
    return 0


if __name__ == "__main__":
    sys.exit(main())
