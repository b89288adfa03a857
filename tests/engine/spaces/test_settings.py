"""The settings of space parsing from dask.config."""
from __future__ import annotations

from engine.spaces.settings import SpaceSettings


def test_fixed_yaw_and_params_from_config():
    import dask

    with dask.config.set({"buildingparser.spaces.walls.min-contrast": 0.7, "buildingparser.spaces.yaw": 10.0}):
        p = SpaceSettings.from_config()
    assert p.walls.min_contrast == 0.7 and p.yaw == 10.0 and p.walls.bin_width == p.bin_width
    assert SpaceSettings.from_config().walls.max_void_ratio == 0.35
