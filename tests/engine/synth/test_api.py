"""``generate``: one call plans, scans and writes; on a dask cluster it gives the same points as in-process."""
from __future__ import annotations

import numpy as np
import pytest

from engine.synth import generate
from tiles.errors import UserError
from tiles.store import open_store


def _columns(path):
    store = open_store(str(path))
    names = ["x", "y", "z", "red", "gt_space", "gt_class", "gt_instance", "point_index"]
    cols = {n: [] for n in names}
    for t in store.tiles:
        for n, v in store.read(t, names).items():
            cols[n].append(v)
    cols = {n: np.concatenate(v) for n, v in cols.items()}
    order = np.argsort(cols["point_index"])
    return {n: v[order] for n, v in cols.items()}


def test_generate_on_a_cluster_equals_generate_here(tmp_path, client):
    kw = dict(seed=9, rooms=5, density=150, yaw=12.0, offset=(500000.0, 4100000.0, 30.0))
    here = generate(tmp_path / "here.zarr", **kw)
    there = generate(tmp_path / "there.zarr", client=client, png=str(tmp_path / "plan.png"), **kw)
    assert here["points"] == there["points"] > 10_000
    assert here["spaces"] == 5 and here["elements"] > 20
    assert set(here) >= {"out", "format", "points", "spaces", "elements", "seconds", "points_per_second"}
    assert here["points_per_second"] > 0
    a, b = _columns(tmp_path / "here.zarr"), _columns(tmp_path / "there.zarr")
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])
    assert (tmp_path / "plan.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    store = open_store(str(tmp_path / "here.zarr"))
    assert store.meta.bounds[0] > 499_900 and store.meta.bounds[1] > 4_099_900


def test_bad_arguments_are_one_line_user_errors(tmp_path):
    with pytest.raises(UserError, match="unknown format"):
        generate(tmp_path / "x", format="ply")
    with pytest.raises(UserError, match="local path"):
        generate("s3://bucket/x", format="s3dis")
    generate(tmp_path / "a.zarr", rooms=2, density=50)
    with pytest.raises(UserError, match="already exists"):
        generate(tmp_path / "a.zarr", rooms=2, density=50)
    assert generate(tmp_path / "a.zarr", rooms=3, density=50, overwrite=True)["spaces"] == 3
