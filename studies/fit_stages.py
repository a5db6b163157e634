"""One plant of the unseen-plants study fitted, its stages listed (where the time goes).

    python -m studies.fit_stages worn          # a named plant (studies.unseen_plants.NAMED)
    python -m studies.fit_stages 10            # a drawn plant, by its seed
    python -m studies.fit_stages lubricated --start-seed 1   # from a seeded start

Prints each stage (name, iterations, wall time [s], converged, cost), the verdict, where the
fit started and the known points' criteria, the noise levels the fit weighed with [SI] and
the fitted values [SI], as JSON lines for comparisons.
"""

from __future__ import annotations

import argparse
import json
import time

from hframe_id.fitting import FitOptions, fit_recordings
from hframe_id.fitting.problem import default_free
from hframe_id.models import build_model
from hframe_id.parameters import load_parameter_file
from studies.mismatch import TABLE_4_2, training_recordings
from studies.seeded_starts import seeded_start
from studies.unseen_plants import NAMED, build_plant, draw_plant, recorder_for


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m studies.fit_stages", description=__doc__)
    parser.add_argument("plant", help="a named plant or a seed of the envelope")
    parser.add_argument(
        "--start-seed",
        type=int,
        help="start from Table 4.2 scaled as start SEED of studies.seeded_starts (default: "
        "Table 4.2 itself)",
    )
    args = parser.parse_args(argv)
    draw = NAMED[args.plant] if args.plant in NAMED else draw_plant(int(args.plant))
    training = training_recordings(build_plant(draw), 0, "steps", recorder_for(draw))
    initial = load_parameter_file(TABLE_4_2)
    if args.start_seed is not None:
        initial = seeded_start(initial, default_free(build_model(initial.variant)), args.start_seed)
    start = time.perf_counter()
    result = fit_recordings(training, initial, FitOptions())
    wall = time.perf_counter() - start
    for s in result.stages:
        print(
            f"{s.name[:70]:70s} it={s.iterations:4d} wall={s.wall_time_s:7.1f} "
            f"converged={s.converged} cost={s.cost:.6g}"
        )
    print(f"{'success' if result.success else 'FAILED'}: {result.message}")
    print(f"wall {wall:.1f} s, noise rounds {result.diagnostics.noise.rounds}")
    print(f"first stage: {result.stages[0].message}")
    known = result.diagnostics.known_points
    print(f"known points: {json.dumps(known.criteria if known else None)}")
    channels = result.diagnostics.noise.channels
    print(json.dumps({name: c.weight_std for name, c in channels.items()}))
    print(json.dumps(result.parameters.values))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
