"""Where a fit's iterations are reported: the options' sink, or lines on stderr."""

from __future__ import annotations

import sys
from dataclasses import replace

from hframe_id.fitting.options import FitOptions, FitProgress


def progress_sink(options: FitOptions):
    """``options.progress``, or with ``options.verbose`` a printer of one line per iteration
    on stderr (with the solver's message at verbose 2), or None."""
    if options.progress is not None:
        return options.progress
    if options.verbose:

        def printer(p: FitProgress) -> None:
            print(
                f"  {p.stage:<30} it {p.iteration:3d}  cost {p.cost:12.6g}  "
                f"step {p.step:8.1e}  defect {p.defect:8.1e}"
                + (f"  {p.message}" if options.verbose > 1 else ""),
                file=sys.stderr,
                flush=True,
            )

        return printer
    return None


def labelled(progress, label: str):
    """A progress sink that prefixes the stage name with ``label`` (None stays None)."""
    if progress is None:
        return None
    return lambda p: progress(replace(p, stage=f"{label}: {p.stage}"))
