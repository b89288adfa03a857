"""Rewriting a COPC file node by node: the same octree and records, edited fields, dropped points, readable."""
from __future__ import annotations

import laspy
import numpy as np
import pytest
from laspy.copc import CopcReader

from tests.tiles.copcdata import OPTS, copc_store, node_entries, rows
from tiles.copc import EXTENSION, write_copc
from tiles.copc_rewrite import rewrite_copc


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    d = tmp_path_factory.mktemp("rewrite")
    path = d / ("points" + EXTENSION)
    write_copc(copc_store(d), str(path), **OPTS)
    return path


def test_an_identity_rewrite_gives_the_same_points_nodes_and_records(source, tmp_path):
    out = tmp_path / ("same" + EXTENSION)
    rep = rewrite_copc(str(source), str(out), lambda p: p)
    h0, info0, e0 = node_entries(source)
    h1, info1, e1 = node_entries(out)
    assert rep["points_in"] == rep["points_out"] == h0.point_count == h1.point_count
    assert [e[:4] + e[6:] for e in e0] == [e[:4] + e[6:] for e in e1]  # every node, with its point count
    assert list(info1.center) == list(info0.center) and (info1.halfsize, info1.spacing) == (info0.halfsize,
                                                                                              info0.spacing)
    np.testing.assert_array_equal(h1.mins, h0.mins)
    np.testing.assert_array_equal(h1.maxs, h0.maxs)
    a, b = laspy.read(str(source)), laspy.read(str(out))
    assert np.array_equal(a.points.array, b.points.array)  # file order too
    def vlrs(h):
        return sorted((v.user_id, v.record_id, bytes(v.record_data_bytes())) for v in h.vlrs if v.user_id != "copc")

    assert vlrs(b.header) == vlrs(a.header) and b.header.vlrs[0].user_id == "copc"  # the info VLR first


def test_edited_fields_and_dropped_points_read_back_through_the_octree(source, tmp_path):
    ref = laspy.read(str(source))
    # the dense patch (x, y in 1001-1001.5, 2001-2001.5) dropped: its deep nodes are left without points
    patch = (np.asarray(ref.x) < 1001.6) & (np.asarray(ref.y) < 2001.6)

    def edit(points):
        s = np.asarray(points["space_id"]).copy()
        points["space_id"] = np.where(s == 1, 2, s)
        return points[~((np.asarray(points.x) < 1001.6) & (np.asarray(points.y) < 2001.6))]

    out = tmp_path / ("edited" + EXTENSION)
    rep = rewrite_copc(str(source), str(out), edit)
    assert rep["points_out"] == int((~patch).sum()) < rep["points_in"] == len(patch)
    want = ref.points.array[~patch].copy()
    want["space_id"] = np.where(want["space_id"] == 1, 2, want["space_id"])
    _, _, nodes = node_entries(out)
    assert any(e[6] == 0 for e in nodes) and len(nodes) == len(node_entries(source)[2])
    with CopcReader.open(str(out)) as r:
        got = r.query()
        assert r.header.point_count == len(want)
    assert np.array_equal(rows(got.array), rows(want))
    assert np.array_equal(laspy.read(str(out)).points.array, want)  # the file order kept
    # the header's bounds are those of the points left
    h = laspy.read(str(out)).header
    np.testing.assert_allclose(h.mins, [want[c].min() * s + o for c, s, o in zip("XYZ", h.scales, h.offsets)])


def test_a_file_that_is_not_copc_is_refused_and_nothing_is_written(tmp_path, source):
    plain = tmp_path / "plain.laz"
    las = laspy.read(str(source))
    las.header.vlrs = [v for v in las.header.vlrs if v.user_id != "copc"]
    las.header.evlrs = [v for v in las.header.evlrs or [] if v.user_id != "copc"]
    las.write(str(plain))
    with pytest.raises(ValueError, match="not a COPC file"):
        rewrite_copc(str(plain), str(tmp_path / ("x" + EXTENSION)), lambda p: p)
    assert not (tmp_path / ("x" + EXTENSION)).exists()
