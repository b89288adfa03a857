"""Shared fixtures: one small LocalCluster for the whole session, paths to shared reference data."""
from __future__ import annotations

import logging
import os
import pathlib

import pytest

import engine.config  # noqa: F401 - buildingparser.* defaults registered before any test sets one
import tiles.config  # noqa: F401

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


@pytest.fixture(scope="session")
def structural_model(tmp_path_factory) -> str:
    """A small ceiling/floor/wall model trained (one mining round) on a tiny generated building: MODEL stem.

    Tests of the whole run use it instead of the shipped model, so that they do
    not depend on how that one was trained and stay fast.
    """
    from engine.cli import main
    from engine.synth import generate

    root = tmp_path_factory.mktemp("structural-model")
    generate(str(root / "train.zarr"), seed=22, rooms=3, density=1200, yaw=50.0)
    rc = main(["train", str(root / "train.zarr"), "--model", str(root / "model"), "--classes",
               "ceiling,floor,wall", "--rounds", "1", "--workers", "1"])
    assert rc == 0
    return str(root / "model")


@pytest.fixture(autouse=True)
def _quiet_progress(monkeypatch):
    """No progress lines in test output unless a test asks for them."""
    import dask

    with dask.config.set({"buildingparser.progress": "never"}):
        yield


os.environ.setdefault("MPLBACKEND", "Agg")
