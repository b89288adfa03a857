"""PLY ingest: binary (both byte orders) and ASCII, every vertex property kept, in order, through export."""
from __future__ import annotations

import laspy
import numpy as np
import pytest

from tiles.errors import UserError
from tiles.export import export, gather_points
from tiles.ingest import ingest

plyfile = pytest.importorskip("plyfile")


def _vertices(n=3000, seed=0):
    rng = np.random.default_rng(seed)
    v = np.zeros(n, dtype=[("x", "f8"), ("y", "f8"), ("z", "f8"), ("red", "u1"), ("green", "u1"), ("blue", "u1"),
                           ("nx", "f4"), ("scalar_Intensity", "f4"), ("classification", "u1"), ("label", "i4"),
                           ("intensity", "u2"), ("gps_time", "f4")])
    xyz = np.round(rng.uniform([500_000, 4_100_000, 0], [500_040, 4_100_025, 3], (n, 3)), 4)
    v["x"], v["y"], v["z"] = xyz.T
    for c in ("red", "green", "blue"):
        v[c] = rng.integers(0, 256, n)
    v["nx"] = rng.normal(size=n).astype("f4")
    v["scalar_Intensity"] = rng.uniform(0, 1, n).astype("f4")
    v["classification"] = rng.integers(0, 40, n)
    v["label"] = rng.integers(-5, 1000, n)
    v["intensity"] = rng.integers(0, 65536, n)
    v["gps_time"] = rng.uniform(0, 10, n)
    return v


def _write(path, v, text=False, byte_order="<", faces=True):
    elements = [plyfile.PlyElement.describe(v, "vertex")]
    if faces:
        f = np.zeros(2, dtype=[("vertex_indices", "i4", (3,))])
        f["vertex_indices"] = [[0, 1, 2], [1, 2, 3]]
        elements.append(plyfile.PlyElement.describe(f, "face"))
    plyfile.PlyData(elements, text=text, byte_order=byte_order).write(str(path))


@pytest.mark.parametrize("text,byte_order", [(False, "<"), (False, ">"), (True, "=")])
def test_every_vertex_and_property_round_trips_through_ingest_and_export(tmp_path, text, byte_order):
    v = _vertices()
    p = tmp_path / "scan.ply"
    _write(p, v, text=text, byte_order=byte_order)
    with pytest.warns(UserWarning, match="face"):
        s = ingest([str(p)], str(tmp_path / "s.zarr"), part_points=700)
    assert s.meta.point_count == len(v)
    if not text:
        assert len(s.meta.parts) == 5  # memory-mapped rows: one task per part
    export(s, str(tmp_path / "out.laz"))
    las = laspy.read(str(tmp_path / "out.laz"))
    np.testing.assert_allclose(np.asarray(las.x), v["x"], atol=1e-4)
    np.testing.assert_allclose(np.asarray(las.z), v["z"], atol=1e-4)
    np.testing.assert_array_equal(np.asarray(las.red) // 257, v["red"])
    np.testing.assert_array_equal(np.asarray(las.blue) // 257, v["blue"])
    np.testing.assert_array_equal(las.points.array["nx"], v["nx"])
    np.testing.assert_array_equal(las.points.array["scalar_Intensity"], v["scalar_Intensity"])
    np.testing.assert_array_equal(las.points.array["label"], v["label"])
    np.testing.assert_array_equal(np.asarray(las.intensity), v["intensity"])  # a 16-bit intensity is LAS's
    np.testing.assert_array_equal(las.points.array["source_gps_time"], v["gps_time"])  # not LAS's f8 gps_time
    # a field named like a reserved dimension is kept under another name, not lost
    np.testing.assert_array_equal(gather_points(s, ["source_classification"])["source_classification"],
                                  v["classification"])
    assert s.meta.sources[0].info["other_elements"] == {"face": 2}


def test_ply_without_coordinates_or_vertices_is_refused_in_one_line(tmp_path):
    v = np.zeros(3, dtype=[("a", "f4"), ("b", "f4"), ("c", "f4")])
    p = tmp_path / "bad.ply"
    plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex")]).write(str(p))
    with pytest.raises(UserError, match="no x/y/z field"):
        ingest([str(p)], str(tmp_path / "s.zarr"))
    q = tmp_path / "junk.ply"
    q.write_bytes(b"not a ply at all\n")
    with pytest.raises(UserError, match="not a readable PLY file"):
        ingest([str(q)], str(tmp_path / "t.zarr"))
    assert not (tmp_path / "s.zarr").exists() and not (tmp_path / "t.zarr").exists()


def test_nan_coordinates_are_refused_not_dropped(tmp_path):
    v = _vertices(50)
    v["z"][7] = np.nan
    p = tmp_path / "nan.ply"
    _write(p, v, faces=False)
    with pytest.raises(UserError, match="non-finite"):
        ingest([str(p)], str(tmp_path / "s.zarr"))
