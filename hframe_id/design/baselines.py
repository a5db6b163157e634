"""The experiments a design is compared with: what users record without one.

- ``six_steps``: the thesis's six open-loop steps (section 4.4, +/-2, 4, 6 V, x- and
  y-motion, 1 s each: ``hframe_id.fitting.designs.standard_designs``), fitted jointly;
- ``prbs``: a pseudo-random binary sequence of +/- the voltage limit on each motor (MATLAB
  ``idinput``'s kind, seeded), switching with probability 1/2 every ``PRBS_CLOCK_S``;
- ``multisine``: ``MultisineProtocol``'s random-phase multisine over the record after the
  pre-roll (its default band, 0.5-10 Hz, widened to the record's second harmonic for records
  shorter than 0.2 s), scaled so that its peak is the voltage limit.

The PRBS and the multisine have the design's duration and voltage limit.
"""

from __future__ import annotations

import numpy as np

from hframe_id.design.excitation import PRE_ROLL_S, Layout
from hframe_id.fitting.designs import standard_designs
from hframe_id.rig.protocols import MultisineProtocol

#: PRBS clock [s]: a 50 Hz band, above the stage's mechanical corner (~3 Hz) and below its
#: belt modes; switching every 1 ms sample would barely move the stage.
PRBS_CLOCK_S = 0.02
#: The multisine's band [Hz] (``hframe-id record --protocol multisine``'s default).
MULTISINE_BAND_HZ = (0.5, 10.0)
#: Seed of the PRBS switching and the multisine phases.
BASELINE_SEED = 0


def prbs(layout: Layout, max_voltage_v: float, seed: int = BASELINE_SEED) -> np.ndarray:
    """(N, 2) voltages [V]: 0 V for the pre-roll, then +/- ``max_voltage_v`` per motor,
    each switching sign with probability 1/2 at every ``PRBS_CLOCK_S`` tick
    (``default_rng(seed)``)."""
    rng = np.random.default_rng(seed)
    clock = max(1, round(PRBS_CLOCK_S / layout.sample_period_s))
    n = layout.samples - layout.pre_roll
    ticks = -(-n // clock)
    flips = rng.uniform(size=(ticks, 2)) < 0.5
    signs = np.where(np.cumsum(flips, axis=0) % 2 == 0, 1.0, -1.0)
    table = np.zeros((layout.samples, 2))
    table[layout.pre_roll :] = max_voltage_v * np.repeat(signs, clock, axis=0)[:n]
    return table


def multisine(layout: Layout, max_voltage_v: float, seed: int = BASELINE_SEED) -> np.ndarray:
    """(N, 2) voltages [V]: ``MultisineProtocol`` over the record after the pre-roll,
    scaled to a peak of ``max_voltage_v`` on the motor with the larger one."""
    period = layout.samples * layout.sample_period_s - PRE_ROLL_S
    low, high = MULTISINE_BAND_HZ
    table = MultisineProtocol(
        1.0,
        low,
        max(high, 2.0 / period),  # a record too short for 10 Hz: its two lowest harmonics
        period,
        layout.samples * layout.sample_period_s,
        PRE_ROLL_S,
        seed,
        2,
    ).table(layout.sample_period_s)
    return table * (max_voltage_v / float(np.max(np.abs(table))))


def six_steps(variant: str, sample_period_s: float) -> list[np.ndarray]:
    """The thesis's six step experiments of ``variant``, (N, 2) voltages [V] each."""
    return [d.inputs for d in standard_designs(variant, sample_period_s)]
