"""PCD ingest: ascii, binary and binary_compressed, packed rgb, every field kept, in order, through export."""
from __future__ import annotations

import laspy
import numpy as np
import pytest

from tiles.errors import UserError
from tiles.export import export
from tiles.ingest import ingest

pypcd4 = pytest.importorskip("pypcd4")


def _cloud(n=2500, seed=1):
    rng = np.random.default_rng(seed)
    xyz = np.round(rng.uniform([0, 0, 0], [30, 20, 3], (n, 3)), 3).astype(np.float32)
    rgb = rng.integers(0, 256, (n, 3)).astype(np.uint32)
    packed = ((rgb[:, 0] << 16) | (rgb[:, 1] << 8) | rgb[:, 2]).view(np.float32)
    intensity = rng.uniform(0, 255, n).astype(np.float32)
    ring = rng.integers(0, 64, n).astype(np.uint16)
    return xyz, rgb, packed, intensity, ring


@pytest.mark.parametrize("encoding", ["ascii", "binary", "binary_compressed"])
def test_every_point_and_field_round_trips_through_ingest_and_export(tmp_path, encoding):
    xyz, rgb, packed, intensity, ring = _cloud()
    # PCL packs rgb in a float32 (binary) or writes it as an unsigned integer (text: a float's text loses its bits)
    rgb_type = np.uint32 if encoding == "ascii" else np.float32
    pc = pypcd4.PointCloud.from_points([xyz[:, 0], xyz[:, 1], xyz[:, 2], packed.view(np.uint32).astype(rgb_type)
                                        if encoding == "ascii" else packed, intensity, ring],
                                       ("x", "y", "z", "rgb", "intensity", "ring"),
                                       (np.float32, np.float32, np.float32, rgb_type, np.float32, np.uint16))
    p = tmp_path / "scan.pcd"
    pc.save(str(p), encoding=pypcd4.Encoding(encoding))
    s = ingest([str(p)], str(tmp_path / "s.zarr"), part_points=600)
    assert s.meta.point_count == len(xyz)
    assert s.meta.sources[0].info["encoding"] == encoding
    export(s, str(tmp_path / "out.laz"))
    las = laspy.read(str(tmp_path / "out.laz"))
    np.testing.assert_allclose(np.stack([las.x, las.y, las.z], axis=1), xyz, atol=2e-4)
    np.testing.assert_array_equal(np.asarray(las.red) // 257, rgb[:, 0])
    np.testing.assert_array_equal(np.asarray(las.green) // 257, rgb[:, 1])
    # a float intensity is no LAS intensity (uint16): kept as it is, beside it
    np.testing.assert_array_equal(las.points.array["source_intensity"], intensity)
    np.testing.assert_array_equal(las.points.array["ring"], ring)


def test_truncated_and_non_pcd_files_are_refused_in_one_line(tmp_path):
    xyz, *_ = _cloud(100)
    pc = pypcd4.PointCloud.from_xyz_points(xyz)
    p = tmp_path / "a.pcd"
    pc.save(str(p), encoding=pypcd4.Encoding.BINARY)
    data = p.read_bytes()
    p.write_bytes(data[:-50])
    with pytest.raises(UserError, match="truncated"):
        ingest([str(p)], str(tmp_path / "s.zarr"))
    q = tmp_path / "b.pcd"
    q.write_bytes(b"\x00\xff" * 100)
    with pytest.raises(UserError, match="not a PCD file"):
        ingest([str(q)], str(tmp_path / "t.zarr"))
