"""Shared fixtures of the design tests: Table 4.2 and one short design made from it."""

from pathlib import Path

import pytest

from hframe_id.design.optimise import DesignOptions, Limits, design_experiment
from hframe_id.parameters import load_parameter_file

MODELS = Path(__file__).resolve().parents[2] / "models"

#: The thesis's travel, with a margin that the shortest doublets at 6 V stay inside.
LIMITS = Limits(6.0, {"x": (-0.2, 0.2), "y": (-0.2, 0.2)}, 0.05)


@pytest.fixture(scope="session")
def table():
    """Table 4.2 (hframe-8)."""
    return load_parameter_file(MODELS / "hframe-8-table4.2.yaml")


@pytest.fixture(scope="session")
def design(table):
    """A 1 s D-optimal design at Table 4.2 within the thesis's limits, without draws (the
    draws multiply the time; ``test_optimise`` checks them apart): ~5 s."""
    return design_experiment(table, 1.0, LIMITS, DesignOptions(draws=0))
