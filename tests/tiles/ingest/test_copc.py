"""COPC input: recognised, ingested in file order like plain LAZ, points read by bounds with their file index."""
from __future__ import annotations

import laspy
import numpy as np
import pytest

from tiles.copc import write_copc
from tiles.export import gather_points
from tiles.info import file_info, format_file_info
from tiles.ingest import ingest
from tiles.ingest.copc import copc_info, node_table, read_bounds


@pytest.fixture(scope="module")
def copc_file(tmp_path_factory):
    """A COPC file of our writer: 5000 points over a few levels, its points in octree order, not input order."""
    d = tmp_path_factory.mktemp("copcin")
    rng = np.random.default_rng(7)
    n = 5000
    las = laspy.LasData(laspy.LasHeader(point_format=6, version="1.4"))
    las.header.scales = np.array([0.001] * 3)
    las.x, las.y, las.z = rng.uniform(0, 30, n), rng.uniform(0, 10, n), rng.uniform(0, 3, n)
    las.gps_time = np.arange(n, dtype=float)
    las.intensity = np.arange(n) % 60000
    las.write(str(d / "in.las"))
    store = ingest([str(d / "in.las")], str(d / "s.zarr"), tile_size=8.0)
    write_copc(store, str(d / "c.copc.laz"), node_points=120, group_points=700, grid_bits=2)
    return d / "c.copc.laz"


def test_ingest_keeps_the_file_order_of_every_field(copc_file, tmp_path):
    ref = laspy.read(str(copc_file))
    assert not np.all(np.diff(ref.gps_time) > 0)  # octree order: not the order points were written in
    with pytest.warns(UserWarning, match="COPC record"):
        store = ingest([str(copc_file)], str(tmp_path / "c.zarr"), tile_size=4.0, part_points=900)
    assert store.meta.sources[0].format == "copc" and store.meta.sources[0].info["copc"] is True
    got = gather_points(store)
    for name, field in (("x", "X"), ("y", "Y"), ("z", "Z"), ("gps_time", "gps_time"), ("intensity", "intensity")):
        np.testing.assert_array_equal(got[name], np.asarray(ref.points.array[field]))


def test_read_bounds_gives_the_points_inside_with_their_file_index(copc_file):
    ref = laspy.read(str(copc_file)).points.array
    lo, hi = [3.0, 2.0, 0.5], [11.0, 7.5, 2.0]
    recs, index = read_bounds(str(copc_file), lo, hi)
    scales = laspy.read(str(copc_file)).header.scales
    keep = np.ones(len(ref), bool)
    for i, c in enumerate("XYZ"):
        keep &= (ref[c] >= np.round(lo[i] / scales[i])) & (ref[c] <= np.round(hi[i] / scales[i]))
    np.testing.assert_array_equal(index, np.flatnonzero(keep))
    assert recs.tobytes() == ref[keep].tobytes()


def test_hierarchy_pages_are_followed(shared_data):
    path = shared_data / "las-samples" / "laspy" / "simple_with_page.copc.laz"
    ref = laspy.read(str(path)).points.array
    with open(path, "rb") as f:
        info = copc_info(laspy.LasHeader.read_from(f))
        table = node_table(f, info)
    assert int(table.counts.sum()) == len(ref)
    h = laspy.read(str(path)).header
    recs, index = read_bounds(str(path), h.mins, h.maxs)
    np.testing.assert_array_equal(index, np.arange(len(ref)))
    assert recs.tobytes() == ref.tobytes()


def test_info_says_copc(copc_file):
    info = file_info(str(copc_file))
    assert info["sources"][0]["format"] == "copc"
    assert "COPC" in format_file_info(info)
