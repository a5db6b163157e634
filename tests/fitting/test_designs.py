"""The standard experiments a fit can ask for (``fitting.designs``): the thesis's open-loop
tests as shipped in datasets/, per variant, at a given sample period."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hframe_id.fitting.designs import standard_designs

DATASETS = Path(__file__).resolve().parents[2] / "datasets"


def _shipped(suffix: str) -> set[str]:
    """Names of the shipped recordings ending in ``suffix`` (the files, not the code)."""
    return {p.stem for p in DATASETS.glob(f"*{suffix}.mcap")}


@pytest.mark.parametrize("variant", ["hframe-8", "hframe-20"])
def test_the_h_frame_designs_are_the_six_shipped_steps(variant):
    """hframe-20 shares the H-frame's experiments, under its own variant."""
    designs = standard_designs(variant, 1e-3)
    names = {d.name for d in designs}
    assert names == _shipped("motion") == {f"{v}V_{m}motion" for v in (2, 4, 6) for m in "xy"}
    assert all(d.variant == variant for d in designs)


def test_the_one_axis_designs_are_the_two_shipped_pulses():
    designs = standard_designs("one-axis", 1e-3)
    assert {d.name for d in designs} == _shipped("oneaxis") == {"5V_oneaxis", "10V_oneaxis"}


@pytest.mark.parametrize(
    ("name", "volts"), [("4V_xmotion", (-4.0, 4.0)), ("6V_ymotion", (-6.0, -6.0))]
)
def test_an_h_frame_step_is_the_section_4_4_step(name, volts):
    """Section 4.4: 50 ms at 0 V, a 0.5 s step (opposite voltages move x, equal ones y),
    1.0 s of record; at 1 ms, 50 + 500 + 450 samples."""
    (design,) = [d for d in standard_designs("hframe-8", 1e-3) if d.name == name]
    expected = np.zeros((1000, 2))
    expected[50:550] = volts
    assert np.array_equal(design.inputs, expected)
    assert design.description


def test_a_one_axis_pulse_is_the_section_2_3_pulse():
    """Section 2.3: 50 ms at 0 V, a 10 V pulse of 0.25 s on the one motor, 0.6 s of record."""
    (design,) = [d for d in standard_designs("one-axis", 1e-3) if d.name == "10V_oneaxis"]
    expected = np.zeros((600, 1))
    expected[50:300] = 10.0
    assert np.array_equal(design.inputs, expected)


def test_the_inputs_follow_the_sample_period():
    """The same experiments at 2 ms: half the samples, the same times."""
    fine = {d.name: d.inputs for d in standard_designs("hframe-8", 1e-3)}
    coarse = {d.name: d.inputs for d in standard_designs("hframe-8", 2e-3)}
    assert coarse.keys() == fine.keys()
    for name, inputs in coarse.items():
        assert np.array_equal(inputs, fine[name][::2]), name


def test_a_variant_without_standard_experiments_has_none():
    assert standard_designs("dc-servo", 1e-3) == []
