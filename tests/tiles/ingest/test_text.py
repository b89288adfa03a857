"""Plain text ingest: blocks cut on line boundaries, the file's layout, every point stored."""
from __future__ import annotations

import numpy as np
import pytest

from tiles.errors import UserError
from tiles.export import gather_points
from tiles.ingest import ingest
from tiles.ingest.text import read_lines_block, sniff


def _cloud(n=5000, seed=0):
    rng = np.random.default_rng(seed)
    xyz = np.round(rng.uniform([0, 0, 0], [40, 25, 3], (n, 3)), 4)
    rgb = rng.integers(0, 256, (n, 3))
    return xyz, rgb


def _write(path, xyz, rgb=None, sep=" ", header=None):
    lines = []
    if header is not None:
        lines.append(header)
    for i in range(len(xyz)):
        vals = [f"{v:.4f}" for v in xyz[i]] + ([str(int(c)) for c in rgb[i]] if rgb is not None else [])
        lines.append(sep.join(vals))
    path.write_text("\n".join(lines) + "\n")


def test_blocks_cut_on_line_boundaries_cover_every_line_once(tmp_path):
    data = b"".join(f"{i} {i} {i}\n".encode() for i in range(500))
    p = tmp_path / "f.xyz"
    p.write_bytes(data)
    seen = []
    with open(p, "rb") as f:
        for start in range(0, len(data), 37):
            _, block = read_lines_block(f, start, min(start + 37, len(data)), 0, len(data))
            seen += [int(line.split()[0]) for line in block.splitlines()]
    assert seen == list(range(500))


def test_sniff_skips_header_and_pts_count_lines(tmp_path):
    p = tmp_path / "a.pts"
    p.write_text("3\n1 2 3 4 5 6\n7 8 9 1 1 1\n2 2 2 2 2 2\n")
    s = sniff(str(p))
    assert (s.ncols, s.header_lines, s.first) == (6, 1, 2)
    q = tmp_path / "b.csv"
    q.write_text("//X,Y,Z\n1,2,3\n")
    s = sniff(str(q))
    assert (s.ncols, s.sep, s.header_lines) == (3, ",", 1)
    r = tmp_path / "c.txt"
    r.write_text("1 2 3 4\n")
    with pytest.raises(UserError, match="4 columns"):
        sniff(str(r))


def test_text_file_ingests_every_point(tmp_path):
    xyz, rgb = _cloud()
    p = tmp_path / "cloud.txt"
    _write(p, xyz, rgb, header="//X Y Z R G B")
    s = ingest([str(p)], str(tmp_path / "s.zarr"), part_points=700)
    assert s.meta.point_count == len(xyz) and len(s.meta.parts) > 3
    assert s.meta.scale == [1e-4] * 3 and s.meta.color_depth == 8 and s.meta.las is None
    got = gather_points(s)
    np.testing.assert_array_equal(got["x"], np.rint(xyz[:, 0] / 1e-4).astype(np.int32))
    np.testing.assert_array_equal(got["green"], rgb[:, 1])
    assert s.meta.sources[0].info["header_lines"] == 1


def test_comma_separated_xyz_and_far_coordinates_get_an_offset(tmp_path):
    xyz, _ = _cloud(800)
    xyz += [500_000.0, 4_100_000.0, 100.0]
    p = tmp_path / "cloud.csv"
    _write(p, xyz, sep=",")
    s = ingest([str(p)], str(tmp_path / "s.zarr"))
    assert s.meta.offset == [500_000.0, 4_100_000.0, 0.0]
    got = gather_points(s, ["x", "y", "z"])
    world = np.stack([got[a] * 1e-4 + o for a, o in zip("xyz", s.meta.offset)], axis=1)
    np.testing.assert_allclose(world, xyz, atol=1e-6)
    assert s.meta.names("las") == []


def test_colour_values_must_be_integers(tmp_path):
    p = tmp_path / "c.txt"
    p.write_text("1 2 3 0.5 0.5 0.5\n")
    with pytest.raises(UserError, match="not integers 0-65535"):
        ingest([str(p)], str(tmp_path / "s.zarr"))
    assert not (tmp_path / "s.zarr").exists()


def test_skip_bad_lines_setting_counts_and_warns(tmp_path):
    import dask

    p = tmp_path / "c.txt"
    p.write_text("1 2 3 4 5 6\n1 2 3\n7 8 9 1 1 1\n")
    with dask.config.set({"buildingparser.ingest.bad-lines": "skip"}), pytest.warns(UserWarning, match="line 2"):
        s = ingest([str(p)], str(tmp_path / "s.zarr"))
    assert s.meta.point_count == 2
    assert s.meta.sources[0].info["skipped_bad_lines"] == 1
