"""Does the equation-error regression (the fit's first stage) depend on the start file?

The regression of ``fitting.equation_error`` from each of the seeded starts of
``studies.seeded_starts`` (Table 4.2, each free parameter x log-uniform [1/2, 2]), on the six
steps of a plant of the unseen-plants study; per free parameter, its value from each start
[SI] and the spread (largest / smallest).

    python -m studies.regression_starts --plant lubricated --starts 5
"""

from __future__ import annotations

import argparse

from hframe_id.fitting import FitOptions
from hframe_id.fitting.equation_error import equation_error_start
from hframe_id.fitting.problem import build_problem, default_free
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.models import build_model
from hframe_id.parameters import load_parameter_file
from studies.mismatch import TABLE_4_2, training_recordings
from studies.seeded_starts import seeded_start
from studies.unseen_plants import NAMED, build_plant, recorder_for


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m studies.regression_starts", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("--plant", choices=sorted(NAMED), default="lubricated")
    parser.add_argument("--starts", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0, help="seeds start k with seed + k")
    args = parser.parse_args(argv)
    draw = NAMED[args.plant]
    recordings = training_recordings(build_plant(draw), 0, "steps", recorder_for(draw))
    table = load_parameter_file(TABLE_4_2)
    free = default_free(build_model(table.variant))
    ends = []
    for k in range(args.starts):
        problem = build_problem(recordings, seeded_start(table, free, args.seed + k), FitOptions())
        ms = MultipleShooting(problem)
        ms.initial_nodes(problem.p_initial)  # the measured positions the regression needs
        p = problem.parameters(
            equation_error_start(
                problem, ms.measured_positions, ms.measured_usable, threads=ms.threads
            )
        )
        named = zip(problem.free, problem.free_names, strict=True)
        ends.append({n: float(p[i]) for i, n in named})
    for name in ends[0]:
        values = [end[name] for end in ends]
        row = " ".join(f"{v:10.4g}" for v in values)
        print(f"{name:12s} {row}  spread {max(values) / min(values):.3g}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
