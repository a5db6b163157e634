"""Model-mismatch study: hframe-8 fits of realistic (hframe-20, stick-slip, current-limited)
plants, judged on a held-out recording against the plant's own section-4.1 reduction.

Per seed: a fresh realistic plant (``realistic_plant("hframe-20", seed)``; seed -1: the shipped
one), a training set recorded with its sensors (``--train``, ``TRAINING_SETS``: the six
section-4.4 steps, or the steps and a 3 V multisine of another phase seed than the held-out
one), and an hframe-8 fit from Table 4.2 (``FitOptions()``: noise levels estimated when the
model cannot follow the data). The fit and the reduction are then simulated on two held-out
recordings (``HELD_OUT``, the same for every training set; simulation fit in percent per
channel, ``hframe_id.validation``). Also the coverage under mismatch: over noise seeds of one
plant, how often each 95 % interval holds the across-seed mean estimate.

Another model than hframe-8 (``--model-file``, a user model, docs/custom-models.md; started
from ``--initial``, by default the model's reference file) is judged against the reduction as
above and against the reduction in that model (``reduction_in_model``: for the current-limited
hframe-8, I_max the plant's amplifier limit).

    python -m studies.mismatch --seeds 0 1 2 --noise-seeds 0 1 2 3 4
    python -m studies.mismatch --train multisine --seeds -1 0 1
    python -m studies.mismatch --initial models/hframe-8-current-limit.yaml --seeds -1
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hframe_id.errors import HframeIdError, OptionError
from hframe_id.fitting import FitOptions, FitResult, fit_recordings
from hframe_id.models import declaration, load_model_file
from hframe_id.parameters import ParameterSet, load_parameter_file
from hframe_id.recordings.recording import Recording
from hframe_id.resources import model_file
from hframe_id.rig.plant import Plant
from hframe_id.rig.protocols import MultisineProtocol, StepProtocol
from hframe_id.rig.realistic import realistic_plant, record_realistic, shipped_plant
from hframe_id.validation.metrics import fit_percent
from hframe_id.validation.replay import simulate_channels

TABLE_4_2 = model_file("hframe-8-table4.2.yaml")
#: The six section-4.4 steps: (volts, motion) with motor 1 / motor 2 = -V / -V (y), -V / +V (x).
STEPS = ((2, "y"), (2, "x"), (4, "y"), (4, "x"), (6, "y"), (6, "x"))
#: Held-out recordings: a 3 V multisine (small motions, many reversals: the friction regime)
#: and a step at a voltage the fit has not seen (the steps' regime).
HELD_OUT = {
    "multisine": MultisineProtocol(3.0, 0.5, 10.0, period_s=2.0, duration_s=2.05, seed=0),
    "5V x step": StepProtocol((-5.0, 5.0), step_s=0.5, duration_s=1.0),
}
#: The six steps as protocols (motor 1 / motor 2 volts as in ``STEPS``).
STEP_PROTOCOLS = tuple(
    StepProtocol((-float(v), float(v if m == "x" else -v)), step_s=0.5, duration_s=1.0)
    for v, m in STEPS
)
#: Training sets (``--train``): protocols fitted jointly, recorded with sensor seeds
#: 1000 noise_seed + index (the held-out ones: 10000 + noise_seed). "multisine" adds the
#: held-out multisine's excitation with other phases (seed 1): the friction regime.
TRAINING_SETS = {
    "steps": STEP_PROTOCOLS,
    "multisine": (
        *STEP_PROTOCOLS,
        MultisineProtocol(3.0, 0.5, 10.0, period_s=2.0, duration_s=2.05, seed=1),
    ),
}


@dataclass
class MismatchTrial:
    """One fit of one plant."""

    seed: int
    train: str  # the training set, a key of TRAINING_SETS
    success: bool
    message: str
    max_defect: float
    wall_time_s: float
    held_out_fit: dict[str, dict[str, float]]  # recording -> channel -> fit [%] of the fit
    reference_fit: dict[str, dict[str, float]]  # the same for the plant's reduction
    channel_rms: dict[str, float]  # SI
    estimates: dict[str, tuple[float, float, float]]  # name -> (estimate, low, high)
    #: concentrated log-likelihood on the training set (``training_criterion``): the fit's,
    #: the reduction's (lower is better)
    criterion: tuple[float, float]
    at_bound: tuple[str, ...] = ()  # free parameters the box stopped (``est.at_bound``)
    #: another model than hframe-8 (``--model-file``): the held-out fit and the criterion of
    #: the reduction in that model (``reduction_in_model``); None for hframe-8
    model_reference_fit: dict[str, dict[str, float]] | None = None
    model_reference_criterion: float | None = None


def plant_for(seed: int) -> Plant:
    """The shipped realistic hframe-20 plant for ``seed`` < 0, else a fresh one."""
    return shipped_plant("hframe-20") if seed < 0 else realistic_plant("hframe-20", seed)


#: How a study records a protocol on a plant: (plant, protocol, sensor seed) -> Recording.
Recorder = Callable[[Plant, object, int], Recording]


def training_recordings(
    plant: Plant, noise_seed: int, train: str = "steps", record: Recorder = record_realistic
) -> list[Recording]:
    """The training set ``train`` (``TRAINING_SETS``) recorded from ``plant`` by ``record``
    (sensor seeds 1000 ``noise_seed`` + index)."""
    return [
        record(plant, protocol, 1000 * noise_seed + i)
        for i, protocol in enumerate(TRAINING_SETS[train])
    ]


def simulation_fit(params: ParameterSet, recording: Recording) -> dict[str, float]:
    """Simulation fit [%] per channel of ``params`` on ``recording``."""
    data, simulated = simulate_channels(params, recording)
    return {
        name: fit_percent(data.measured[:, j], simulated[:, j], data.valid[:, j])
        for j, name in enumerate(data.names)
    }


def training_criterion(params: ParameterSet, recordings: list[Recording]) -> float:
    """The criterion the noise estimation minimises, evaluated by free-run simulation over
    the training recordings: sum_j N_j log rms_j over the channels j (N_j valid samples,
    rms_j [SI] the simulation residual's). Lower is better; a fit at the best optimum has it
    below any other parameter set's, the plant's reduction included."""
    squares: dict[str, float] = {}
    counts: dict[str, int] = {}
    for recording in recordings:
        data, simulated = simulate_channels(params, recording)
        for j, name in enumerate(data.names):
            valid = data.valid[:, j]
            residual = data.measured[valid, j] - simulated[valid, j]
            squares[name] = squares.get(name, 0.0) + float(residual @ residual)
            counts[name] = counts.get(name, 0) + int(valid.sum())
    return sum(n * 0.5 * np.log(squares[k] / n) for k, n in counts.items())


def fit_and_record_held_out(
    plant: Plant,
    training: list[Recording],
    start_file: Path,
    held_out: dict,
    noise_seed: int,
    options: FitOptions | None,
    record: Recorder = record_realistic,
) -> tuple[FitResult, float, dict[str, Recording]]:
    """The fit of ``training`` from ``start_file``, its wall time [s], and the held-out
    protocols recorded from ``plant`` by ``record`` (sensor seed 10000 + ``noise_seed``)."""
    start = time.perf_counter()
    result = fit_recordings(training, load_parameter_file(start_file), options)
    wall = time.perf_counter() - start
    recordings = {
        name: record(plant, protocol, 10_000 + noise_seed) for name, protocol in held_out.items()
    }
    return result, wall, recordings


def reduction_in_model(plant: Plant, start: ParameterSet) -> ParameterSet:
    """The plant's reduction (``plant.reference()``) in the model of ``start``: its values, an
    ``I_max`` the plant's amplifier current limit, any other parameter ``start``'s."""
    values = {k: v for k, v in plant.reference().values.items() if k in start.values}
    if "I_max" in start.values:
        values["I_max"] = plant.constants.current_limit_a
    return start.replace_values(**values)


def reference_in_fitted_model(
    plant: Plant,
    start: Path,
    result: FitResult,
    training: list[Recording],
    held_out: dict[str, Recording],
) -> dict:
    """``MismatchTrial``'s ``model_reference_fit`` and ``model_reference_criterion``: for a fit
    in another model than the plant's reference (a user model), the plant's reference in
    that model (``reduction_in_model``) judged on the held-out and training recordings;
    None for both otherwise."""
    if result.parameters.variant == plant.reference().variant:
        return {"model_reference_fit": None, "model_reference_criterion": None}
    own = reduction_in_model(plant, load_parameter_file(start))
    return {
        "model_reference_fit": {n: simulation_fit(own, r) for n, r in held_out.items()},
        "model_reference_criterion": training_criterion(own, training),
    }


def run_trial(
    seed: int,
    noise_seed: int = 0,
    options: FitOptions | None = None,
    train: str = "steps",
    start: Path = TABLE_4_2,
    plant: Plant | None = None,
    record: Recorder = record_realistic,
) -> MismatchTrial:
    """Fit one realistic plant's training set ``train`` from the parameter file ``start``
    (Table 4.2) and judge it on the held-out recordings (``HELD_OUT``); a model other than
    hframe-8 also against the reduction in that model (``reduction_in_model``). The plant is
    ``plant_for(seed)`` unless ``plant`` is given (``seed`` then only labels the trial), its
    recordings made by ``record`` (default: the realistic sim rig)."""
    plant = plant or plant_for(seed)
    training = training_recordings(plant, noise_seed, train, record)
    result, wall, held_out = fit_and_record_held_out(
        plant, training, start, HELD_OUT, noise_seed, options, record
    )
    return MismatchTrial(
        seed=seed,
        train=train,
        success=result.success,
        message=result.message,
        max_defect=float(result.stages[-1].max_defect),
        wall_time_s=wall,
        held_out_fit={n: simulation_fit(result.parameters, r) for n, r in held_out.items()},
        reference_fit={n: simulation_fit(plant.reference(), r) for n, r in held_out.items()},
        channel_rms=dict(result.diagnostics.channel_rms),
        estimates={
            name: (est.estimate, *est.ci95) for name, est in result.estimates.items() if est.free
        },
        criterion=(
            training_criterion(result.parameters, training),
            training_criterion(plant.reference(), training),
        ),
        at_bound=tuple(name for name, est in result.estimates.items() if est.at_bound),
        **reference_in_fitted_model(plant, start, result, training, held_out),
    )


def coverage_of_mean(trials: list[MismatchTrial]) -> float:
    """Share of the reported intervals that hold the across-seed mean estimate."""
    names = list(trials[0].estimates)
    hits = total = 0
    for name in names:
        mean = float(np.mean([t.estimates[name][0] for t in trials]))
        for t in trials:
            _, low, high = t.estimates[name]
            hits += int(low <= mean <= high)
            total += 1
    return hits / total


def comparison_text(t: MismatchTrial, reference: str) -> tuple[str, str]:
    """The training criteria and the held-out fits of a trial, each as
    "(fitted/<reference>[/<reference> in the fitted model]) a/b[/c]" text."""
    fits = [t.held_out_fit, t.reference_fit]
    criteria = list(t.criterion)
    columns = f"fitted/{reference}"
    if t.model_reference_fit is not None:
        fits.append(t.model_reference_fit)
        criteria.append(t.model_reference_criterion)
        columns += f"/{reference} in the fitted model"
    channels = "; ".join(
        f"{name}: "
        + ", ".join(f"{k} " + "/".join(f"{f[name][k]:.2f}" for f in fits) + " %" for k in ks)
        for name, ks in t.held_out_fit.items()
    )
    return (
        f"({columns}) {'/'.join(f'{c:.1f}' for c in criteria)}",
        f"({columns}): {channels}",
    )


def _line(t: MismatchTrial) -> str:
    criteria, held_out = comparison_text(t, "reduction")
    return (
        f"seed {t.seed:3d} train={t.train} success={t.success} at_bound=[{','.join(t.at_bound)}] "
        f"defect {t.max_defect:.1e} std time {t.wall_time_s:.1f} s training criterion "
        f"{criteria}; held-out fit {held_out}; {t.message}"
    )


def parse_latency(text: str) -> dict[str, int]:
    """``FitOptions.latency_samples`` from ``CHANNEL=SAMPLES,...`` (whole samples, 1 ms each
    at 1 kHz); empty text: none. A malformed item is an ``OptionError`` naming it."""
    latency = {}
    for item in (part.strip() for part in text.split(",")):
        if not item:
            continue
        name, sep, value = (part.strip() for part in item.partition("="))
        if not sep or not name or not value:
            raise OptionError(f"--latency must look like CHANNEL=SAMPLES, got {item!r}")
        try:
            latency[name] = int(value)
        except ValueError:
            raise OptionError(
                f"--latency {name}: {value!r} is not a whole number of samples"
            ) from None
    return latency


def _latency_argument(text: str) -> dict[str, int]:
    """``parse_latency`` for argparse: a malformed value is a usage error, not a traceback."""
    try:
        return parse_latency(text)
    except OptionError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def add_latency_argument(parser: argparse.ArgumentParser, shipped: str) -> None:
    """``--latency``, parsed into ``FitOptions.latency_samples``; ``shipped``: the shipped
    plant's value, for the help."""
    parser.add_argument(
        "--latency",
        type=_latency_argument,
        default="",
        help="FitOptions.latency_samples as CHANNEL=SAMPLES,... (the shipped plant: one "
        f"sample of actuation delay and two of laser latency: {shipped})",
    )


def _model_file_argument(path: str) -> str:
    """``load_model_file`` for argparse (the variant name): a bad file is a usage error."""
    try:
        return load_model_file(path).name
    except HframeIdError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def add_model_arguments(parser: argparse.ArgumentParser, variant: str, table: str) -> None:
    """``--model-file`` (a user model instead of ``variant``) and ``--initial`` (the start
    parameter file instead of ``table``); ``start_file`` resolves them."""
    parser.add_argument(
        "--model-file",
        type=_model_file_argument,
        metavar="FILE.py",
        help=f"fit this user model (docs/custom-models.md) instead of {variant}",
    )
    parser.add_argument(
        "--initial",
        type=Path,
        metavar="FILE.yaml",
        help=f"start parameter file (default: {table}; with --model-file its reference file)",
    )


def start_file(parser: argparse.ArgumentParser, args: argparse.Namespace, table: Path) -> Path:
    """The start parameter file of ``add_model_arguments``' options: ``--initial``, else the
    user model's reference file, else ``table``; one of another model is a usage error."""
    start = args.initial or (
        declaration(args.model_file).reference_file if args.model_file else table
    )
    try:
        variant = load_parameter_file(start).variant
    except HframeIdError as err:
        parser.error(f"--initial: {err}")
    if args.model_file and variant != args.model_file:
        parser.error(f"--initial {start} is a {variant} file, --model-file's is {args.model_file}")
    return start


def main(argv: list[str] | None = None) -> int:
    """The command line of this study (``--help``); prints one line per trial."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="*", default=[-1], help="plants (-1 shipped)")
    parser.add_argument(
        "--noise-seeds", type=int, nargs="*", default=[], help="coverage: noise seeds of plant -1"
    )
    parser.add_argument(
        "--train",
        choices=tuple(TRAINING_SETS),
        default="steps",
        help="training set: the six steps, or the steps and a 3 V multisine (phase seed 1)",
    )
    add_latency_argument(parser, "phi1=1,phi2=1,x=3,y=3")
    add_model_arguments(parser, "hframe-8", "Table 4.2")
    args = parser.parse_args(argv)
    start = start_file(parser, args, TABLE_4_2)
    options = FitOptions(latency_samples=args.latency)
    for seed in args.seeds:
        print(_line(run_trial(seed, options=options, train=args.train, start=start)), flush=True)
    if args.noise_seeds:
        trials = [
            run_trial(-1, noise_seed=s, options=options, train=args.train, start=start)
            for s in args.noise_seeds
        ]
        for t in trials:
            print(_line(t), flush=True)
        print(f"coverage of the across-seed mean: {coverage_of_mean(trials):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
