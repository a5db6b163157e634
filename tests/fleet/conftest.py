"""Fixtures shared by the fleet tests."""

import pytest
from distributed import Client, LocalCluster


@pytest.fixture(scope="module")
def client():
    """One worker thread in this process: fast to start, enough for the fault tests."""
    with (
        LocalCluster(
            n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0"
        ) as cluster,
        Client(cluster) as client,
    ):
        yield client
