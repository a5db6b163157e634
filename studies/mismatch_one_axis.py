"""Model-mismatch study, one-axis: Table 2.3 fits of realistic one-axis plants (stick-slip,
Stribeck, 8 A current limit, delays), judged on held-out recordings against the plant's own
parameters.

Per seed: the realistic one-axis plant (``realistic_plant("one-axis", seed)``; seed -1: the
shipped one, ``datasets/realistic/plants/one-axis-realistic.yaml``), the two section-2.3 pulses
of ``datasets/realistic`` (5 V and 10 V for 0.25 s, 50 ms pre-roll, 0.6 s record; ``PULSES``)
recorded with its sensors (sensor seeds 1000 noise_seed + index, as ``mismatch``), and a joint
fit of both from Table 2.3 (``FitOptions()``: what ``hframe-id fit 5V_oneaxis.mcap
10V_oneaxis.mcap --model one-axis`` does). The fit and the plant's own parameter set
(``plant.reference()``: its base set, for the shipped plant ``datasets/realistic/truth/
one-axis.yaml``) are simulated on held-out recordings (``HELD_OUT``: a 7 V pulse of the same
shape and a small 2 V rms multisine; sensor seed 10000 + noise_seed) and scored by simulation
fit in percent per channel (``mismatch.simulation_fit``).

At 0.71 ohm an 8 A current limit binds from about 5.7 V: the 10 V and the 7 V pulses drive
the stage alike (the model, without the limit, expects them to differ).

    python -m studies.mismatch_one_axis --seeds -1 0 1 2
    python -m studies.mismatch_one_axis --seeds -1 --latency phi1=1,x=3
    python -m studies.mismatch_one_axis --seeds -1 0 1 2 --latency phi1=1,x=3 \
        --model-file models/one_axis_current_limit.py
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

from hframe_id.fitting import FitOptions
from hframe_id.recordings.recording import Recording
from hframe_id.resources import model_file
from hframe_id.rig.plant import Plant
from hframe_id.rig.protocols import MultisineProtocol, PulseProtocol
from hframe_id.rig.realistic import realistic_plant, record_realistic, shipped_plant
from studies.mismatch import (
    MismatchTrial,
    add_latency_argument,
    add_model_arguments,
    comparison_text,
    fit_and_record_held_out,
    reference_in_fitted_model,
    simulation_fit,
    start_file,
    training_criterion,
)

TABLE_2_3 = model_file("one-axis-table2.3.yaml")
#: The two fitted pulses of ``datasets/realistic`` (5V_oneaxis.mcap, 10V_oneaxis.mcap): motor 1
#: at 5 V and 10 V for 0.25 s after a 50 ms pre-roll, 0.6 s recorded.
PULSES = tuple(
    PulseProtocol(volts, width_s=0.25, duration_s=0.6, pre_roll_s=0.05) for volts in (5.0, 10.0)
)
#: Held-out recordings: a pulse between the two (same shape) and a small multisine (2 V rms,
#: 0.5-10 Hz, one 2 s period: the cart stays within about +/- 1 cm, the friction regime).
HELD_OUT = {
    "7V pulse": PulseProtocol(7.0, width_s=0.25, duration_s=0.6, pre_roll_s=0.05),
    "multisine": MultisineProtocol(
        2.0, 0.5, 10.0, period_s=2.0, duration_s=2.05, pre_roll_s=0.05, seed=0, n_inputs=1
    ),
}


@dataclass
class OneAxisTrial(MismatchTrial):
    """One fit of one one-axis plant (``train`` is ``"pulses"``; ``reference_fit`` and the
    criterion's second entry are the plant's own parameter set's)."""

    at_bound: tuple[str, ...]  # free parameters the box stopped (``est.at_bound``)


def plant_for(seed: int) -> Plant:
    """The shipped realistic one-axis plant for ``seed`` < 0, else a fresh one."""
    return shipped_plant("one-axis") if seed < 0 else realistic_plant("one-axis", seed)


def pulse_recordings(plant: Plant, noise_seed: int) -> list[Recording]:
    """The two pulses (``PULSES``) recorded from ``plant`` (sensor seeds 1000 ``noise_seed``
    + index)."""
    return [
        record_realistic(plant, protocol, seed=1000 * noise_seed + i)
        for i, protocol in enumerate(PULSES)
    ]


def run_trial(
    seed: int, noise_seed: int = 0, options: FitOptions | None = None, start: Path = TABLE_2_3
) -> OneAxisTrial:
    """Fit one realistic one-axis plant's two pulses from the parameter file ``start`` (Table
    2.3) and judge the fit and the plant's own parameters on the held-out recordings
    (``HELD_OUT``); a model other than one-axis also against the plant's own parameters in
    that model (``reduction_in_model``: with the plant's current limit as I_max)."""
    plant = plant_for(seed)
    training = pulse_recordings(plant, noise_seed)
    result, wall, held_out = fit_and_record_held_out(
        plant, training, start, HELD_OUT, noise_seed, options
    )
    own = plant.reference()
    return OneAxisTrial(
        seed=seed,
        train="pulses",
        success=result.success,
        message=result.message,
        max_defect=float(result.stages[-1].max_defect),
        wall_time_s=wall,
        held_out_fit={n: simulation_fit(result.parameters, r) for n, r in held_out.items()},
        reference_fit={n: simulation_fit(own, r) for n, r in held_out.items()},
        channel_rms=dict(result.diagnostics.channel_rms),
        estimates={
            name: (est.estimate, *est.ci95) for name, est in result.estimates.items() if est.free
        },
        criterion=(
            training_criterion(result.parameters, training),
            training_criterion(own, training),
        ),
        at_bound=tuple(name for name, est in result.estimates.items() if est.at_bound),
        **reference_in_fitted_model(plant, start, result, training, held_out),
    )


def _line(t: OneAxisTrial) -> str:
    criteria, held_out = comparison_text(t, "plant")
    rms = t.channel_rms
    return (
        f"seed {t.seed:3d} success={t.success} at_bound=[{','.join(t.at_bound)}] defect "
        f"{t.max_defect:.1e} std time {t.wall_time_s:.1f} s rms phi1 {rms['phi1']:.2e} rad "
        f"x {1e3 * rms['x']:.3f} mm training criterion {criteria}; held-out fit {held_out}; "
        f"{t.message}"
    )


def main(argv: list[str] | None = None) -> int:
    """The command line of this study (``--help``); prints one line per trial."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="*", default=[-1], help="plants (-1 shipped)")
    add_latency_argument(parser, "phi1=1,x=3")
    add_model_arguments(parser, "one-axis", "Table 2.3")
    args = parser.parse_args(argv)
    start = start_file(parser, args, TABLE_2_3)
    options = FitOptions(latency_samples=args.latency)
    for seed in args.seeds:
        print(_line(run_trial(seed, options=options, start=start)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
