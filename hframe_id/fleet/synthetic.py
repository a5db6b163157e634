"""A synthetic fleet recorded with the sim rig: rigs that differ, weekly runs, some aging.

Each rig is Table 4.2 (``models/hframe-8-table4.2.yaml``) with every default-free parameter
times a log-uniform factor within x/÷ ``RIG_SPREAD`` (rig-to-rig spread). Every week each
parameter is further multiplied by exp(N(0, ``WEEKLY_JITTER``)) (remounting, temperature: the
week-to-week scatter of a healthy rig), and on the aged rigs the aging parameters move
linearly from x1 in week 0 to the factor of their kind in the last week (``AGING``, cycled
over ``n_rigs // 2`` rigs drawn at random; ``belt-mild`` stays below a 10 % drift threshold on
purpose). A weekly run is ``EXPERIMENTS``: three 1 s steps, recorded unpaced with the rig's
sensor models. ``DIR/manifest.yaml`` lists the fits, ``DIR/aging.yaml`` what was aged and by
how much (factor in the last week against week 0, without the jitter).

With ``plant="realistic"`` each rig is a realistic sim-rig plant instead
(``hframe_id.rig.realistic.realistic_plant("hframe-20", seed)``: an hframe-20 plant with
stick-slip friction, a current limit and delays, docs/realistic-rig.md), fitted with hframe-8
from Table 4.2 as before; the jitter moves every drawn plant parameter, the aging moves the
plant's own parameters (``REALISTIC_AGING``), and ``aging.yaml`` gives both the plant's factors
and the factors they make in the plant's section-4.1 reduction to the fitted model.
"""

from __future__ import annotations

import datetime as dt
import math
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from hframe_id.errors import OptionError
from hframe_id.fitting.problem import default_free
from hframe_id.fleet.manifest import FORMAT_VERSION
from hframe_id.models import build_model, declaration
from hframe_id.parameters import ParameterSet, load_parameter_file
from hframe_id.parameters.reduce import reduce_to_hframe8
from hframe_id.rig.logger import RunOptions, run_experiment
from hframe_id.rig.plant import Plant
from hframe_id.rig.protocols import StepProtocol
from hframe_id.rig.realistic import NOT_DRAWN, realistic_plant
from hframe_id.rig.sim import SimRig

VARIANT = "hframe-8"
#: Rig-to-rig spread: each parameter within x/÷ this of Table 4.2.
RIG_SPREAD = 1.1
#: Relative std of a healthy rig's week-to-week scatter of every parameter.
WEEKLY_JITTER = 0.01
#: Aging kinds: parameter -> factor reached in the last week (against week 0).
AGING: tuple[tuple[str, dict[str, float]], ...] = (
    ("belt", {"k_l": 0.7, "k_r": 0.7, "k_b": 0.7}),
    ("friction", {"b_cart": 1.5, "b_bridge": 1.5, "F_c_cart": 1.5, "F_c_bridge": 1.5}),
    ("motor", {"g_2": 0.8}),
    ("belt-mild", {"k_l": 0.95, "k_r": 0.95, "k_b": 0.95}),
)
#: A weekly identification run: (name, motor 1 [V], motor 2 [V]); 50 ms pre-roll, a 0.5 s
#: step, 1 s recorded (section 4.4's protocol, fewer and shorter runs).
EXPERIMENTS = (("4V_y", -4.0, -4.0), ("4V_x", -4.0, 4.0), ("2V_x", -2.0, 2.0))
#: Plants the fleet can be recorded from: the fitted model itself (``sim``) or realistic
#: hframe-20 plants (``realistic``).
PLANTS = ("sim", "realistic")
#: The aging of ``AGING`` on a realistic (hframe-20) plant: the belt kinds scale all nine
#: belt springs (so the reduced k_l, k_r, k_b by the same factor: springs in series);
#: friction and motor parameters have the same names in both models.
REALISTIC_SPRINGS = tuple(f"k_{i}" for i in range(1, 10))
REALISTIC_AGING: dict[str, dict[str, float]] = {
    "belt": dict.fromkeys(REALISTIC_SPRINGS, 0.7),
    "friction": {"b_cart": 1.5, "b_bridge": 1.5, "F_c_cart": 1.5, "F_c_bridge": 1.5},
    "motor": {"g_2": 0.8},
    "belt-mild": dict.fromkeys(REALISTIC_SPRINGS, 0.95),
}
#: Week 0's runs start here; a rig's run is 10 min after the previous rig's.
FIRST_RUN = dt.datetime(2026, 1, 5, 8, 0, tzinfo=dt.UTC)


def make_fleet(
    n_rigs: int, n_weeks: int, seed: int, out: str | Path, progress=None, plant: str = "sim"
) -> Path:
    """Record the fleet into ``out`` (created if absent; ``hframe-id fleet make`` gives a new
    folder, put in place when the fleet is complete); returns the manifest's path.
    ``progress`` is called with (rig, week) after each weekly run. ``plant``: ``"sim"`` (the
    fitted model's own plants) or ``"realistic"``."""
    if plant not in PLANTS:
        raise OptionError(f"--plant must be one of {', '.join(PLANTS)}, got {plant!r}")
    if n_rigs < 1:
        raise OptionError(f"--rigs must be >= 1, got {n_rigs}")
    if n_weeks < 2:
        raise OptionError(f"--weeks must be >= 2 (drift needs a baseline), got {n_weeks}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    table = declaration(VARIANT).reference_file
    initial = out / table.name
    shutil.copyfile(table, initial)
    base = load_parameter_file(table, VARIANT)
    free = default_free(build_model(VARIANT))
    rigs = [f"rig-{i + 1:02d}" for i in range(n_rigs)]
    aged_rigs = sorted(rng.choice(n_rigs, size=n_rigs // 2, replace=False).tolist())
    aging = {rigs[i]: AGING[k % len(AGING)] for k, i in enumerate(aged_rigs)}
    reduced_aging: dict[str, dict[str, float]] = {}
    if plant == "realistic":
        aging = {rig: (kind, REALISTIC_AGING[kind]) for rig, (kind, _) in aging.items()}
    fits = []
    for r, rig in enumerate(rigs):
        if plant == "realistic":
            rig_plant = realistic_plant("hframe-20", seed * 1000 + r)
            nominal = rig_plant.parameters
            jittered = [n for n in nominal.values if n not in NOT_DRAWN]
        else:
            nominal = _scaled(base, {n: _log_uniform(rng, RIG_SPREAD) for n in free})
            jittered = free
        for week in range(n_weeks):
            factors = {n: math.exp(rng.normal(0.0, WEEKLY_JITTER)) for n in jittered}
            if rig in aging:
                for name, final in aging[rig][1].items():
                    factors[name] *= 1 + (final - 1) * week / (n_weeks - 1)
            params = _scaled(nominal, factors)
            params.title = f"{rig} in week {week} (synthetic fleet, seed {seed})"
            recorded = params
            if plant == "realistic":
                recorded = rig_plant.with_parameters(params, title=params.title, seed=None)
            when = FIRST_RUN + dt.timedelta(weeks=week, minutes=10 * r)
            files = _record_week(
                recorded, out, rig, week, when, seed=(seed * 1000 + r) * 100 + week
            )
            fits.append({"rig": rig, "time": when.isoformat(), "recordings": files})
            if progress is not None:
                progress(rig, week)
        if plant == "realistic" and rig in aging:
            reduced_aging[rig] = _reduced_factors(nominal, aging[rig][1])
    manifest = {
        "format_version": FORMAT_VERSION,
        "title": f"synthetic fleet: {n_rigs} rigs x {n_weeks} weeks, seed {seed}"
        + (", realistic plants" if plant == "realistic" else ""),
        "defaults": {"model": VARIANT, "initial": initial.name},
        "fits": fits,
    }
    path = out / "manifest.yaml"
    path.write_text(yaml.safe_dump(manifest, sort_keys=False, width=100))
    (out / "aging.yaml").write_text(
        yaml.safe_dump(
            _aging_doc(n_rigs, n_weeks, seed, rigs, aging, plant, reduced_aging), sort_keys=False
        )
    )
    return path


def _reduced_factors(nominal: ParameterSet, plant_factors: dict[str, float]) -> dict[str, float]:
    """What the plant's aging does to its section-4.1 reduction (the fitted model's values):
    the last week's reduction over week 0's, without the jitter, for the parameters it
    moves by more than 0.1 %."""
    before = reduce_to_hframe8(nominal).values
    after = reduce_to_hframe8(_scaled(nominal, plant_factors)).values
    ratios = {n: after[n] / before[n] for n in after if before[n]}
    return {n: round(float(f), 4) for n, f in ratios.items() if abs(f - 1) > 1e-3}


def _log_uniform(rng: np.random.Generator, spread: float) -> float:
    return math.exp(rng.uniform(-math.log(spread), math.log(spread)))


def _scaled(params: ParameterSet, factors: dict[str, float]) -> ParameterSet:
    return params.replace_values(**{n: params.values[n] * f for n, f in factors.items()})


def _record_week(
    plant: ParameterSet | Plant, out: Path, rig: str, week: int, when: dt.datetime, seed: int
) -> list[str]:
    """Record one weekly run; the recordings' paths relative to ``out``."""
    folder = out / rig
    folder.mkdir(exist_ok=True)
    files = []
    for k, (name, v1, v2) in enumerate(EXPERIMENTS):
        path = folder / f"week-{week:02d}-{name}.mcap"
        summary = run_experiment(
            SimRig(plant, seed=seed * 10 + k, paced=False),
            StepProtocol((v1, v2), step_s=0.5, duration_s=1.0, pre_roll_s=0.05),
            RunOptions(
                out=path,
                operator="hframe-id fleet make",
                reproducible=True,
                start_time=when + dt.timedelta(seconds=5 * k),
                handle_signals=False,
                extra_experiment={"rig": rig, "week": week},
            ),
        )
        if summary.aborted:
            raise OptionError(f"{path}: the sim run aborted ({summary.abort_reason})")
        files.append(str(path.relative_to(out)))
    return files


def _aging_doc(n_rigs, n_weeks, seed, rigs, aging, plant, reduced) -> dict[str, Any]:
    if plant == "realistic":
        # Fitted-model factors first (what drift is judged on), the plant's beside them.
        aged = [
            {"rig": rig, "kind": kind, "last_week_factor": reduced[rig],
             "plant_last_week_factor": dict(factors)}
            for rig, (kind, factors) in sorted(aging.items())
        ]  # fmt: skip
    else:
        aged = [
            {"rig": rig, "kind": kind, "last_week_factor": dict(factors)}
            for rig, (kind, factors) in sorted(aging.items())
        ]
    return {
        "seed": seed,
        "rigs": n_rigs,
        "weeks": n_weeks,
        "plant": plant,
        "rig_spread": RIG_SPREAD if plant == "sim" else "realistic_plant: 1 +/- U(0.10, 0.20)",
        "weekly_jitter_relative_std": WEEKLY_JITTER,
        "aged": aged,
        "not_aged": [rig for rig in rigs if rig not in aging],
    }
