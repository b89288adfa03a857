"""Shared fixtures: one small LocalCluster for the whole session, paths to shared reference data."""
from __future__ import annotations

import logging
import os
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
SHARED_DATA = SHARED / "data"


@pytest.fixture(scope="session")
def client():
    """A 2-worker LocalCluster shared by the tests that need dask."""
    from distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=logging.ERROR, memory_limit="4GiB")
    c = Client(cluster)
    yield c
    c.close()
    cluster.close()


@pytest.fixture(scope="session")
def shared_data() -> pathlib.Path:
    """``../shared/data``; tests that need it skip when it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"reference data not found at {SHARED_DATA} (the shared/ folder beside the project)")
    return SHARED_DATA


@pytest.fixture(autouse=True)
def _quiet_progress(monkeypatch):
    """No progress lines in test output unless a test asks for them."""
    import dask

    with dask.config.set({"buildingparser.progress": "never"}):
        yield


os.environ.setdefault("MPLBACKEND", "Agg")
