"""The designed excitation: a sequence of doublets on the two motors, within the voltage limit.

A design is ``PRE_ROLL_S`` at 0 V (the fit sees the record start at rest), then equal blocks,
each a doublet on each motor, repeated ``cycles_i`` times over the block:

    u_i(t) = a d_i s(c_i t / T_block),   s = +1 for the first quarter of a cycle, -1 for its
    middle half, +1 for its last quarter,

with c_i in ``CYCLES`` (0: the motor rests), d_1 = 1 and d_2 = +/-1 (the motors together or
against each other), so that |u_i| <= a <= the voltage limit. A doublet's input integrates to
zero over each cycle: a stage that follows its voltage like an integrator (the H-frame's speed
follows the voltage within ~50 ms) comes back to where the doublet started,
so that blocks can be chained without the motion drifting to the end stops, and the lasers
(+/-5 cm) stay in range. Amplitude sets the speed (Coulomb against viscous friction), cycles
the frequency (inertia at low, belt stiffness at high ones) and, through the two motors'
cycles and signs, which axes and belts move (flight-test practice: the doublet is the
classic identification input).

Rest after the blocks (a remainder shorter than a block) is 0 V.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hframe_id.errors import OptionError
from hframe_id.fitting.dataset import REST_SAMPLES

#: 0 V recorded first [s]: the protocols' pre-roll (``hframe_id.rig.protocols``), longer
#: than the fit's rest test (``REST_SAMPLES``, 10 ms at 1 kHz).
PRE_ROLL_S = 0.05
#: Samples at 0 V before a candidate block simulated on its own: the fit's rest test
#: (``hframe_id.fitting.problem.REST_SAMPLES``) sees it start at rest, as the design's
#: pre-roll does; at rest the integration is stiff and costs most, so no more.
CANDIDATE_REST = REST_SAMPLES
#: Block length the design aims for [s]: the slowest doublet (one cycle) then pushes for
#: 125 ms, about 2.5 of the H-frame's mechanical time constants (~50 ms), long enough to
#: reach the steady speed that separates Coulomb from viscous friction.
BLOCK_S = 0.5
#: Amplitudes of the candidate blocks, as fractions of the voltage limit: the limit itself
#: (bang-bang inputs carry the most information per second under an amplitude limit), and
#: half of it, a second speed that separates Coulomb from viscous friction (a third level,
#: 1/3, was measured never to be chosen by the D criterion and cost a third more time).
AMPLITUDE_FRACTIONS = (1.0, 0.5)
#: Doublets per block on each motor (0: the motor rests): 2 to 32 Hz in a 0.5 s block,
#: from the stage's mechanical corner to below its belt modes.
CYCLES = (0, 1, 2, 4, 8, 16)


@dataclass(frozen=True)
class Block:
    """One block of a design: on motor i a doublet of ``amplitude_v`` [V] repeated
    ``cycles[i]`` times over the block (0: 0 V), motor 2's sign flipped if ``opposite``."""

    amplitude_v: float
    cycles: tuple[int, int]
    opposite: bool = False

    def __post_init__(self) -> None:
        if not (math.isfinite(self.amplitude_v) and self.amplitude_v >= 0):
            raise OptionError(f"block amplitude must be >= 0 V, got {self.amplitude_v!r}")
        if len(self.cycles) != 2 or min(self.cycles) < 0:
            raise OptionError(f"a block needs two cycle counts >= 0, got {self.cycles}")

    def table(self, samples: int) -> np.ndarray:
        """(samples, 2) voltages [V] of the block."""
        k = np.arange(samples)
        table = np.zeros((samples, 2))
        for i, cycles in enumerate(self.cycles):
            phase = (k * cycles / samples) % 1.0  # position within a cycle, [0, 1)
            shape = np.where((phase < 0.25) | (phase >= 0.75), 1.0, -1.0)
            sign = -1.0 if (i == 1 and self.opposite) else 1.0
            table[:, i] = self.amplitude_v * sign * shape * (cycles > 0)
        return table

    def describe(self) -> str:
        """``6 V: u1 x2, u2 x4 opposite``: amplitude, cycles per motor."""
        parts = [f"u{i + 1} x{c}" for i, c in enumerate(self.cycles) if c]
        flip = " opposite" if self.opposite and all(self.cycles) else ""
        return f"{self.amplitude_v:.3g} V: {', '.join(parts)}{flip}"


@dataclass(frozen=True)
class Layout:
    """How a design of ``duration_s`` [s] at ``sample_period_s`` [s] is cut: the pre-roll,
    ``n_blocks`` blocks of ``block_samples`` each, then rest to the end."""

    duration_s: float
    sample_period_s: float = 1e-3

    def __post_init__(self) -> None:
        if not (math.isfinite(self.duration_s) and self.duration_s > 0):
            raise OptionError(f"--duration must be > 0 s, got {self.duration_s!r}")
        if self.n_blocks < 1 or self.block_samples < 8:
            raise OptionError(
                f"--duration {self.duration_s:g} s leaves no room for a block after the "
                f"{PRE_ROLL_S:g} s pre-roll; give at least {PRE_ROLL_S + 0.1:g} s"
            )

    @property
    def samples(self) -> int:
        """Samples of the whole design."""
        return round(self.duration_s / self.sample_period_s)

    @property
    def pre_roll(self) -> int:
        """Samples at 0 V first."""
        return round(PRE_ROLL_S / self.sample_period_s)

    @property
    def n_blocks(self) -> int:
        """Blocks: as many of about ``BLOCK_S`` as fit, at least one."""
        usable = self.samples - self.pre_roll
        return max(1, round(usable * self.sample_period_s / BLOCK_S)) if usable > 0 else 0

    @property
    def block_samples(self) -> int:
        """Samples per block."""
        return (self.samples - self.pre_roll) // max(self.n_blocks, 1)

    def table(self, blocks: Sequence[Block]) -> np.ndarray:
        """(samples, 2) voltages [V] of a design made of ``blocks`` (at most ``n_blocks``)."""
        if len(blocks) > self.n_blocks:
            raise OptionError(f"{len(blocks)} blocks, the layout holds {self.n_blocks}")
        table = np.zeros((self.samples, 2))
        start = self.pre_roll
        for block in blocks:
            table[start : start + self.block_samples] = block.table(self.block_samples)
            start += self.block_samples
        return table

    def block_table(self, block: Block) -> np.ndarray:
        """(``CANDIDATE_REST`` + block samples, 2) voltages [V]: one block from rest, as a
        candidate experiment on its own."""
        table = np.zeros((CANDIDATE_REST + self.block_samples, 2))
        table[CANDIDATE_REST:] = block.table(self.block_samples)
        return table


def candidate_blocks(max_voltage_v: float) -> list[Block]:
    """Every block of ``AMPLITUDE_FRACTIONS`` of ``max_voltage_v`` [V] x ``CYCLES`` on each
    motor (not both resting) x motor 2's sign (where both move)."""
    return [
        Block(fraction * max_voltage_v, (c1, c2), opposite)
        for fraction in AMPLITUDE_FRACTIONS
        for c1 in CYCLES
        for c2 in CYCLES
        for opposite in ((False, True) if c1 and c2 else (False,))
        if c1 or c2
    ]


def sequence_rows(table: np.ndarray, sample_period_s: float) -> list[tuple[float, ...]]:
    """The rows of a CSV voltage sequence (``load_sequence_csv``) that plays ``table``:
    (time [s], u1 [V], u2 [V]) at the first sample and at every change, and at the last
    sample, so that the sequence lasts the table's length."""
    change = np.r_[True, np.any(np.diff(table, axis=0) != 0, axis=1)]
    change[-1] = True
    return [
        (round(k * sample_period_s, 9), *(float(v) for v in table[k]))
        for k in np.flatnonzero(change)
    ]


def sequence_text(table: np.ndarray, sample_period_s: float) -> str:
    """The CSV text (header ``time [s],u1 [V],u2 [V]``) of ``sequence_rows``."""
    lines = ["time [s],u1 [V],u2 [V]"]
    lines += [",".join(f"{v:.9g}" for v in row) for row in sequence_rows(table, sample_period_s)]
    return "\n".join(lines) + "\n"
