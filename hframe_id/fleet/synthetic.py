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
from hframe_id.rig.logger import RunOptions, run_experiment
from hframe_id.rig.protocols import StepProtocol
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
#: Week 0's runs start here; a rig's run is 10 min after the previous rig's.
FIRST_RUN = dt.datetime(2026, 1, 5, 8, 0, tzinfo=dt.UTC)


def make_fleet(n_rigs: int, n_weeks: int, seed: int, out: str | Path, progress=None) -> Path:
    """Record the fleet into ``out`` (which must not exist or be empty); returns the
    manifest's path. ``progress`` is called with (rig, week) after each weekly run."""
    if n_rigs < 1:
        raise OptionError(f"--rigs must be >= 1, got {n_rigs}")
    if n_weeks < 2:
        raise OptionError(f"--weeks must be >= 2 (drift needs a baseline), got {n_weeks}")
    out = Path(out)
    if out.exists() and any(out.iterdir()):
        raise OptionError(f"--out {out}: exists and is not empty")
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
    fits = []
    for r, rig in enumerate(rigs):
        nominal = _scaled(base, {n: _log_uniform(rng, RIG_SPREAD) for n in free})
        for week in range(n_weeks):
            factors = {n: math.exp(rng.normal(0.0, WEEKLY_JITTER)) for n in free}
            if rig in aging:
                for name, final in aging[rig][1].items():
                    factors[name] *= 1 + (final - 1) * week / (n_weeks - 1)
            plant = _scaled(nominal, factors)
            plant.title = f"{rig} in week {week} (synthetic fleet, seed {seed})"
            when = FIRST_RUN + dt.timedelta(weeks=week, minutes=10 * r)
            files = _record_week(plant, out, rig, week, when, seed=(seed * 1000 + r) * 100 + week)
            fits.append({"rig": rig, "time": when.isoformat(), "recordings": files})
            if progress is not None:
                progress(rig, week)
    manifest = {
        "format_version": FORMAT_VERSION,
        "title": f"synthetic fleet: {n_rigs} rigs x {n_weeks} weeks, seed {seed}",
        "defaults": {"model": VARIANT, "initial": initial.name},
        "fits": fits,
    }
    path = out / "manifest.yaml"
    path.write_text(yaml.safe_dump(manifest, sort_keys=False, width=100))
    (out / "aging.yaml").write_text(
        yaml.safe_dump(_aging_doc(n_rigs, n_weeks, seed, rigs, aging), sort_keys=False)
    )
    return path


def _log_uniform(rng: np.random.Generator, spread: float) -> float:
    return math.exp(rng.uniform(-math.log(spread), math.log(spread)))


def _scaled(params: ParameterSet, factors: dict[str, float]) -> ParameterSet:
    return params.replace_values(**{n: params.values[n] * f for n, f in factors.items()})


def _record_week(
    plant: ParameterSet, out: Path, rig: str, week: int, when: dt.datetime, seed: int
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


def _aging_doc(n_rigs, n_weeks, seed, rigs, aging) -> dict[str, Any]:
    return {
        "seed": seed,
        "rigs": n_rigs,
        "weeks": n_weeks,
        "rig_spread": RIG_SPREAD,
        "weekly_jitter_relative_std": WEEKLY_JITTER,
        "aged": [
            {"rig": rig, "kind": kind, "last_week_factor": dict(factors)}
            for rig, (kind, factors) in sorted(aging.items())
        ],
        "not_aged": [rig for rig in rigs if rig not in aging],
    }
