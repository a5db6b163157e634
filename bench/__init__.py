"""Benchmarks (``make bench``, ``python -m bench``): speed as ratios against baselines measured
in the same run. Run from the checkout; not shipped in the package.

Timings on these shared 2-core machines are noisy, so every section reports the median of
repeats and a ratio against a baseline timed in the same process, never an absolute pass/fail.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable


def median_time(function: Callable[[], object], repeats: int = 5, warmup: int = 1) -> float:
    """Median wall time [s] of ``function()`` over ``repeats`` runs after ``warmup`` runs."""
    for _ in range(warmup):
        function()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def heading(title: str) -> None:
    """Print a section heading (markdown level 2)."""
    print(f"\n## {title}\n", flush=True)
