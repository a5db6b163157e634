"""Standard experiments a fit can ask for: the thesis's open-loop tests (as shipped in datasets/).

The candidates of the experiment-design advice (``hframe_id.fitting.design_advice``): the
input sequences only, per variant, at a given sample period.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hframe_id.rig.datasets import DATASETS


@dataclass(frozen=True)
class Design:
    """A named input sequence for a model variant."""

    name: str
    variant: str
    inputs: np.ndarray  # (N, n_u) commanded voltages [V]
    description: str


#: Truth file of the shipped datasets -> model variant.
_VARIANT_OF_TRUTH = {"hframe-8-rig": "hframe-8", "one-axis-rig": "one-axis"}


def standard_designs(variant: str, sample_period_s: float) -> list[Design]:
    """The thesis's open-loop experiments for a variant (section 4.4 steps for the H-frame,
    section 2.3 pulses for one-axis). hframe-20 shares the H-frame's experiments."""
    wanted = "hframe-8" if variant.startswith("hframe") else variant
    designs = []
    for spec in DATASETS:
        if _VARIANT_OF_TRUTH.get(spec.truth) != wanted:
            continue
        name = spec.file.removesuffix(".mcap")
        designs.append(
            Design(name, variant, spec.protocol.table(sample_period_s), spec.description)
        )
    return designs
