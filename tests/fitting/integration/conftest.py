"""Integration tests of the fitter: whole fits and whole commands, several modules at once
(seconds each). Every test in this folder is marked ``integration`` by its path, so
``pytest -m "not integration"`` runs the unit tests alone."""

from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent


def pytest_collection_modifyitems(config, items):
    for item in items:
        if HERE in Path(item.path).resolve().parents:
            item.add_marker(pytest.mark.integration)
