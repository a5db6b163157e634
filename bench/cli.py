"""Command-line start-up: ``hframe-id --help``, ``fit --help`` and ``params show`` as new
processes, against a baseline timed in the same run that first imports what every command
needs (what the command line did before its imports were made lazy: 2.4-3.9 s for
``--help`` and 2.5-2.7 s for ``fit --help`` on the shared 2-core machine). Then one fit of
4V_xmotion.mcap: its wall time against the solver's own time in the same process (the rest
is start-up, reading, report and plots; issue 12's target: at most 2), median ratio of
``REPEATS`` runs with and without plots, interleaved, and the plotted fit's wall time
against the solver's time without plots (the figure worker can slow the solve's start).
"""

from __future__ import annotations

import re
import subprocess
import sys
import tempfile
import time

from bench import heading
from hframe_id.resources import dataset_file, model_file

#: What the commands import between them: a process that imports these up front answers
#: ``--help`` as the eager command line did.
EAGER = (
    "hframe_id.fitting.fit",
    "hframe_id.fitting.report",
    "hframe_id.validation",
    "hframe_id.validation.plots",
    "hframe_id.control.reproduction",
    "hframe_id.analysis.export",
    "hframe_id.rig.logger",
    "hframe_id.simulation.open_loop",
    "hframe_id.recordings.importer",
)
REPEATS = 5
SOLVER_TIME = re.compile(r"iterations in all stages, ([0-9.]+) s\)")


def _wall(argv: list[str], eager: bool = False) -> float:
    """Median wall time [s] of ``hframe-id ARGV`` in a new Python process."""
    preload = "".join(f"import {name}\n" for name in EAGER) if eager else ""
    code = f"import sys\n{preload}from hframe_id.cli import main\nsys.exit(main(sys.argv[1:]))"
    times = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, check=True)
        times.append(time.perf_counter() - start)
    return sorted(times)[REPEATS // 2]


def _fit(extra: list[str]) -> tuple[float, float]:
    """(wall time, solver time) [s] of ``hframe-id fit 4V_xmotion.mcap`` into a scratch folder."""
    with tempfile.TemporaryDirectory() as out:
        argv = ["fit", str(dataset_file("4V_xmotion.mcap")), "--out-dir", out, "--quiet"]
        start = time.perf_counter()
        done = subprocess.run(
            [sys.executable, "-m", "hframe_id", *argv, *extra],
            capture_output=True,
            text=True,
            check=True,
        )
        wall = time.perf_counter() - start
    return wall, float(SOLVER_TIME.search(done.stdout).group(1))


def run() -> None:
    """Print the start-up times of three commands (lazy vs eager imports) and of two fits."""
    heading("command line")
    params = str(model_file("hframe-8-table4.2.yaml"))
    print(f"median of {REPEATS} new processes; baseline: the same with every command's imports")
    print(f"{'command':<32} {'lazy [s]':>9} {'eager [s]':>10} {'ratio':>7}")
    for argv in (["--help"], ["fit", "--help"], ["params", "show", params]):
        lazy, eager = _wall(argv), _wall(argv, eager=True)
        label = "hframe-id " + " ".join(argv[:2])
        print(f"{label:<32} {lazy:>9.2f} {eager:>10.2f} {lazy / eager:>7.2f}", flush=True)
    variants = ([], ["--no-plots"])
    runs = [[_fit(extra) for extra in variants] for _ in range(REPEATS)]
    print(f"fit, median of {REPEATS} interleaved runs: wall time / the solver's time")
    for k, extra in enumerate(variants):
        ratios = sorted(wall / solver for wall, solver in (run[k] for run in runs))
        walls = sorted(run[k][0] for run in runs)
        solvers = sorted(run[k][1] for run in runs)
        label = " ".join(["fit 4V_xmotion.mcap", *extra])
        print(
            f"{label}: {walls[REPEATS // 2]:.2f} s wall, solver {solvers[REPEATS // 2]:.2f} s, "
            f"ratio {ratios[REPEATS // 2]:.2f} (range {ratios[0]:.2f}-{ratios[-1]:.2f})",
            flush=True,
        )
    # The figure worker's matplotlib import can overlap the solve's start and slow it: the
    # plotted fit's wall time against the solver's time of the fit without plots as well.
    undisturbed = sorted(run[0][0] / run[1][1] for run in runs)
    print(
        f"fit 4V_xmotion.mcap: wall time / the solver's time without plots: ratio "
        f"{undisturbed[REPEATS // 2]:.2f} (range {undisturbed[0]:.2f}-{undisturbed[-1]:.2f})",
        flush=True,
    )
