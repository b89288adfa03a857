"""Ingesting in many small parts on the 2-worker cluster gives exactly the store of a one-part ingest."""
from __future__ import annotations

import laspy
import numpy as np
import pytest

from tiles.ingest import ingest


def _building_like(n=60_000, seed=7):
    """Points on the walls, floor and ceiling of a few rooms, with colour and intensity."""
    rng = np.random.default_rng(seed)
    kind = rng.integers(0, 3, n)
    xyz = rng.uniform([0, 0, 0], [36.0, 22.0, 3.0], (n, 3))
    xyz[kind == 0, 2] = rng.normal(0.0, 0.003, (kind == 0).sum())
    xyz[kind == 1, 2] = rng.normal(3.0, 0.003, (kind == 1).sum())
    walls = kind == 2
    xyz[walls, 0] = np.round(xyz[walls, 0] / 6.0) * 6.0 + rng.normal(0, 0.003, walls.sum())
    return xyz, rng


def _compare_stores(a, b):
    assert a.meta.point_count == b.meta.point_count
    assert [t.to_json() for t in a.tiles] == [t.to_json() for t in b.tiles]
    assert a.meta.dimensions == b.meta.dimensions
    names = [d.name for d in a.meta.dimensions]
    for ta, tb in zip(a.tiles, b.tiles):
        ra, rb = a.read(ta, names), b.read(tb, names)
        for name in names:
            np.testing.assert_array_equal(ra[name], rb[name], err_msg=f"{ta.name}/{name}")
            assert ra[name].dtype == rb[name].dtype
        offs = b.part_offsets(tb)
        assert offs[0] == 0 and offs[-1] == tb.count and np.all(np.diff(offs) >= 0)


def test_las_in_many_parts_on_the_cluster_equals_one_part(tmp_path, client):
    xyz, rng = _building_like()
    las = laspy.LasData(laspy.LasHeader(point_format=7, version="1.4"))
    las.header.scales = np.array([0.0005] * 3)
    las.header.offsets = np.array([1000.0, 2000.0, 0.0])
    las.x, las.y, las.z = xyz[:, 0] + 1000.0, xyz[:, 1] + 2000.0, xyz[:, 2]
    las.intensity = rng.integers(0, 65535, len(xyz))
    las.red, las.green, las.blue = (rng.integers(0, 65535, len(xyz)) for _ in range(3))
    las.gps_time = np.arange(len(xyz)) * 1e-3
    las.write(str(tmp_path / "b.las"))
    one = ingest([str(tmp_path / "b.las")], str(tmp_path / "one.zarr"), part_points=10**9)
    many = ingest([str(tmp_path / "b.las")], str(tmp_path / "many.zarr"), part_points=997, client=client)
    assert len(one.meta.parts) == 1 and len(many.meta.parts) == 61 and len(many.tiles) >= 12
    _compare_stores(one, many)


@pytest.mark.parametrize("fmt", ["txt"])
def test_text_in_many_parts_on_the_cluster_equals_one_part(tmp_path, client, fmt):
    xyz, rng = _building_like(20_000, seed=3)
    rgb = rng.integers(0, 256, (len(xyz), 3))
    text = "\n".join(f"{x:.4f} {y:.4f} {z:.4f} {r} {g} {b}" for (x, y, z), (r, g, b) in zip(xyz, rgb))
    (tmp_path / f"c.{fmt}").write_text(text + "\n")
    one = ingest([str(tmp_path / f"c.{fmt}")], str(tmp_path / "one.zarr"), part_points=10**9)
    many = ingest([str(tmp_path / f"c.{fmt}")], str(tmp_path / "many.zarr"), part_points=333, client=client)
    assert len(one.meta.parts) == 1 and len(many.meta.parts) > 40
    _compare_stores(one, many)
