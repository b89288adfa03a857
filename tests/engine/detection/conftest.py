"""Generated buildings and a small model trained on one of them, shared by the detection tests (made once per session)."""
from __future__ import annotations

import pytest

from engine.cli import main
from engine.detection.model import Model
from engine.synth import generate
from tiles.store import open_store

#: The classes of the ``trained`` model.
STRUCTURE = ("ceiling", "floor", "wall")


@pytest.fixture(scope="session")
def buildings(tmp_path_factory):
    """Two small generated buildings (different seeds, rotated): one to train on, one to test on."""
    root = tmp_path_factory.mktemp("det")
    out = {}
    for name, seed, yaw in (("train", 11, 20.0), ("test", 12, 63.0)):
        generate(str(root / f"{name}.zarr"), seed=seed, rooms=3, density=1200, yaw=yaw)
        out[name] = open_store(str(root / f"{name}.zarr"))
    return root, out


@pytest.fixture(scope="session")
def trained(buildings, client):
    """A structural-only model trained with the command line (one mining round)."""
    root, stores = buildings
    model = root / "model"
    rc = main(["train", stores["train"].url, "--model", str(model), "--classes", ",".join(STRUCTURE),
               "--rounds", "1", "--scheduler", client.scheduler.address])
    assert rc == 0
    return Model.load(model)
