"""Mismatch-effects study: which realistic-plant effect makes hframe-8 fits lose held out.

Which of the realistic plant's effects make an hframe-8 fit generalize worse than the plant's
own reduction: the mismatch study on the shipped plant (or fresh ones, ``--seeds``) with its
effects taken away.

The mismatch study (``studies.mismatch``: six section-4.4 steps fitted from Table 4.2 with
the default options, judged on a held-out multisine and 5 V step against the plant's
section-4.1 reduction) is run on variants of a realistic hframe-20 plant (``variants``): each
effect of docs/realistic-rig.md removed alone, all of them removed but the 20th-order belts
and the Table 2.2 stick-slip law, the 20th-order belts with the models' own smooth friction
(the plain sim rig), and the stick-slip law alone (a plant that is the reduction itself,
recorded by the realistic rig with every other effect removed), trained on the six steps or
on the steps and a multisine (``--train``). Each variant is judged
against its own reduction, which for every variant but the last is the base plant's.

    python -m studies.mismatch_effects
    python -m studies.mismatch_effects --variants shipped stick-slip-only
    python -m studies.mismatch_effects --train multisine
    python -m studies.mismatch_effects --variants no-current-limit --seeds -1 0 1
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, replace

from hframe_id.recordings.recording import Recording
from hframe_id.recordings.simulated import simulate_recording
from hframe_id.rig.plant import Plant
from hframe_id.rig.realistic import record_realistic, shipped_plant
from studies.mismatch import (
    TRAINING_SETS,
    MismatchTrial,
    Recorder,
    comparison_text,
    plant_for,
    run_trial,
)

#: Sample period of every recording [s] (the realistic rig's default).
SAMPLE_PERIOD_S = 1e-3


@dataclass(frozen=True)
class Variant:
    """A plant of the study and how it is recorded."""

    description: str
    plant: Plant
    record: Recorder = record_realistic


def record_smooth(plant: Plant, protocol, seed: int) -> Recording:
    """``protocol`` recorded by the plain sim rig from ``plant``'s base parameters: the
    models' own smooth friction, constant stiffness, no delays, no current limit."""
    return simulate_recording(plant.parameters, protocol.table(SAMPLE_PERIOD_S), seed=seed)


def without_effects(plant: Plant) -> Plant:
    """``plant`` with only its belts (its model) and the Table 2.2 stick-slip law: no Stribeck
    peak, no current limit, no actuation delay or sensor latency, constant stiffness."""
    return replace(
        plant,
        constants=replace(plant.constants, static_to_coulomb_ratio=1.0, current_limit_a=math.inf),
        actuation_delay_samples=0,
        encoder_latency_samples=0,
        laser_latency_samples=0,
        position_dependent_stiffness=False,
    )


def variants(base: Plant | None = None) -> dict[str, Variant]:
    """The plants of the study, by name (docs/studies/2026-11-24-model-mismatch-hframe-8.md,
    "Where the held-out gap comes from"): ``base`` (default: the shipped hframe-20 plant) with
    its effects taken away."""
    plant = base or shipped_plant("hframe-20")
    constants = plant.constants
    bare = without_effects(plant)
    return {
        "shipped": Variant("the base plant, every effect", plant),
        "no-stribeck": Variant(
            "without the Stribeck peak (F_s = F_c)",
            replace(plant, constants=replace(constants, static_to_coulomb_ratio=1.0)),
        ),
        "no-current-limit": Variant(
            "without the current limit",
            replace(plant, constants=replace(constants, current_limit_a=math.inf)),
        ),
        "no-delays": Variant(
            "without the actuation delay and the laser latency",
            replace(plant, actuation_delay_samples=0, laser_latency_samples=0),
        ),
        "constant-stiffness": Variant(
            "constant belt stiffness",
            replace(plant, position_dependent_stiffness=False),
        ),
        "belts-and-stick-slip": Variant("20th-order belts and Table 2.2 stick-slip only", bare),
        "belts-smooth-friction": Variant(
            "20th-order belts with the models' smooth friction (plain sim rig)",
            plant,
            record_smooth,
        ),
        "stick-slip-only": Variant(
            "the reduction itself as the plant, with Table 2.2 stick-slip",
            bare.with_parameters(plant.reference()),
        ),
    }


def at_least_as_good(trial: MismatchTrial) -> int:
    """Held-out channel cases where the fit's simulation fit is at least the reduction's."""
    return sum(
        trial.held_out_fit[name][channel] >= trial.reference_fit[name][channel]
        for name in trial.held_out_fit
        for channel in trial.held_out_fit[name]
    )


def variant_line(name: str, trial: MismatchTrial) -> str:
    """One line per variant and plant: outcome, count, training criteria and held-out fits
    (``studies.mismatch.comparison_text``)."""
    cases = sum(len(channels) for channels in trial.held_out_fit.values())
    criteria, held_out = comparison_text(trial, "reduction")
    bound = ", ".join(trial.at_bound) or "-"
    return (
        f"{name} (plant {trial.seed}): success={trial.success} time {trial.wall_time_s:.0f} s; "
        f"fitted >= reduction in {at_least_as_good(trial)} of {cases}; training criterion "
        f"{criteria}; held-out fit {held_out}; at bound: {bound}"
    )


def main(argv: list[str] | None = None) -> int:
    """The command line of this study (``--help``); prints one line per variant and plant."""
    described = variants()
    parser = argparse.ArgumentParser(
        description=__doc__.splitlines()[0],
        epilog="variants: "
        + "; ".join(f"{name}: {variant.description}" for name, variant in described.items()),
    )
    parser.add_argument(
        "--variants",
        nargs="+",
        choices=tuple(described),
        default=list(described),
        help="plants to run (default: all)",
    )
    parser.add_argument(
        "--train",
        choices=tuple(TRAINING_SETS),
        default="steps",
        help="training set: the six steps, or the steps and a 3 V multisine (phase seed 1)",
    )
    parser.add_argument(
        "--seeds",
        type=int,
        nargs="+",
        default=[-1],
        help="base plants: -1 the shipped one, others fresh (realistic_plant seeds)",
    )
    args = parser.parse_args(argv)
    for seed in args.seeds:
        plants = variants(plant_for(seed))
        for name in args.variants:
            variant = plants[name]
            trial = run_trial(seed, train=args.train, plant=variant.plant, record=variant.record)
            print(variant_line(name, trial), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
