"""Plug SciPy's ``least_squares`` into hframe-id's solver seam, from outside the package.

The fit's all-window stage is handed to a registered solver as a ``Stage``; this one takes
its single-shooting view (residuals and Jacobian in the estimated initial states and the
free log-parameters, ``hframe_id.fitting.single_shooting``) and minimises it with SciPy's
trust-region reflective method within the parameters' bounds. The start stages stay the
default's, and the statistics read the same Jacobian at the end.

    python examples/scipy_solver.py            # the six shipped steps, both solvers

prints each free parameter by both solvers and their largest relative difference.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from hframe_id.fitting import FitOptions, fit_recordings
from hframe_id.fitting.solvers import Stage, register_solver
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.reader import read_recording

ROOT = Path(__file__).resolve().parents[1]
STEPS = [f"{v}V_{axis}motion.mcap" for v in (2, 4, 6) for axis in ("x", "y")]


class ScipyLeastSquares:
    """SciPy ``least_squares`` (trust-region reflective) on the stage's single shooting.

    Tolerances: ``ftol`` and ``xtol`` 1e-12 (relative), far below the 1e-4 at which the
    estimates are compared with the default solver's (``FitOptions.step_tol`` 1e-6)."""

    penalty_fallback = True
    description = "SciPy least_squares (trust-region reflective) on single shooting"

    def solve(self, stage: Stage):
        shooting = stage.single_shooting()
        lower, upper = shooting.bounds()
        solution = least_squares(
            shooting.residual,
            np.clip(shooting.start(), lower, upper),
            jac=shooting.jacobian,
            bounds=(lower, upper),
            method="trf",
            x_scale="jac",
            ftol=1e-12,
            xtol=1e-12,
            gtol=1e-12,
            max_nfev=stage.options.max_iterations,
        )
        shooting.finish(solution.x)
        return stage.finish("SciPy", solution.nfev, solution.status > 0, solution.message)


def main() -> int:
    register_solver("scipy-least-squares", ScipyLeastSquares())
    recordings = [read_recording(ROOT / "datasets" / name) for name in STEPS]
    table = load_parameter_file(ROOT / "models" / "hframe-8-table4.2.yaml")
    fits = {
        solver: fit_recordings(recordings, table, FitOptions(solver=solver))
        for solver in ("gauss-newton", "scipy-least-squares")
    }
    default, scipy = fits["gauss-newton"], fits["scipy-least-squares"]
    worst = 0.0
    print(f"{'parameter':<22} {'gauss-newton':>14} {'scipy':>14} {'relative':>10}")
    for name in default.free_names:
        a = default.parameters.values[name]
        b = scipy.parameters.values[name]
        relative = abs(b - a) / abs(a)
        worst = max(worst, relative)
        print(f"{default.estimates[name].key:<22} {a:>14.8g} {b:>14.8g} {relative:>10.2e}")
    print(f"success: gauss-newton {default.success}, scipy {scipy.success}")
    print(f"largest relative difference {worst:.2e}")
    return 0 if default.success and scipy.success else 1


if __name__ == "__main__":
    sys.exit(main())
