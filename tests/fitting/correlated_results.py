"""A stand-in fit result with a given correlation matrix, for the report's correlation tests."""

from types import SimpleNamespace

import numpy as np

#: Free parameters of the stand-in.
NAMES = ("k_l", "k_r", "J_M1", "B_M1")

#: k_l-k_r strongly, k_r-J_M1 strongly (a chain: one group of three), B_M1 apart.
CHAIN = [
    [1.0, 0.97, 0.5, 0.1],
    [0.97, 1.0, -0.93, 0.0],
    [0.5, -0.93, 1.0, 0.2],
    [0.1, 0.0, 0.2, 1.0],
]


def correlated_result(correlation, identified_by=None):
    """A result whose free parameters ``NAMES`` have ``correlation``; ``identified_by`` maps
    a name to the recordings that identify it."""
    identified_by = identified_by or {}
    estimates = {
        n: SimpleNamespace(key=f"{n} [unit]", identified_by=identified_by.get(n, ())) for n in NAMES
    }
    return SimpleNamespace(free_names=NAMES, correlation=np.array(correlation), estimates=estimates)
