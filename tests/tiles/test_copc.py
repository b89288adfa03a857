"""COPC export: laspy's CopcReader reads it; the same points as points.laz; a sound octree; deterministic."""
from __future__ import annotations

import struct

import laspy
import numpy as np
import pytest
from laspy.copc import Bounds, CopcReader

from tests.tiles.copcdata import OPTS, copc_store, node_entries, rows
from tiles.copc import EXTENSION, write_copc
from tiles.errors import UserError
from tiles.export import export


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    return copc_store(tmp_path_factory.mktemp("copc"))


@pytest.fixture(scope="module")
def written(store, tmp_path_factory):
    d = tmp_path_factory.mktemp("out")
    export(store, str(d / "points.laz"))
    rep = write_copc(store, str(d / ("points" + EXTENSION)), **OPTS)
    return d / "points.laz", d / ("points" + EXTENSION), rep


def test_copc_reader_gives_every_point_of_points_laz(written):
    laz, copc, rep = written
    ref = laspy.read(str(laz))
    with CopcReader.open(str(copc)) as r:
        pts = r.query()
        assert r.header.point_format.id == 7 and r.header.version.minor == 4
        assert r.header.point_count == len(ref.points) == rep["points"]
        np.testing.assert_array_equal(r.header.mins, ref.header.mins)
        np.testing.assert_array_equal(r.header.maxs, ref.header.maxs)
        assert list(r.header.point_format.extra_dimension_names) == list(ref.point_format.extra_dimension_names)
        np.testing.assert_array_equal(r.header.number_of_points_by_return, ref.header.number_of_points_by_return)
        assert (r.copc_info.gps_min, r.copc_info.gps_max) == (ref.gps_time.min(), ref.gps_time.max())
        ours = [(v.user_id, v.record_id, bytes(v.record_data_bytes())) for v in r.header.vlrs
                if v.user_id not in ("copc", "laszip encoded")]
        theirs = [(v.user_id, v.record_id, bytes(v.record_data_bytes())) for v in ref.header.vlrs
                  if v.user_id != "laszip encoded"]
        assert ours == theirs  # class lookup, extra bytes (with their ranges), CRS
    assert pts.array.dtype == ref.points.array.dtype
    assert np.array_equal(rows(pts.array), rows(ref.points.array))
    plain = laspy.read(str(copc))  # a plain LAZ reader reads it too (variable-size chunk table)
    assert np.array_equal(rows(plain.points.array), rows(ref.points.array))
    assert rep["levels"] >= 4 and rep["groups"] > 1


def test_bounds_query_gives_the_points_inside(written):
    laz, copc, _ = written
    ref = laspy.read(str(laz))
    lo, hi = np.array([1000.5, 2000.2, -1.0]), np.array([1004.0, 2006.0, 1.5])
    with CopcReader.open(str(copc)) as r:
        got = r.query(Bounds(lo, hi))
    mn = np.round((lo - ref.header.offsets) / ref.header.scales)
    mx = np.round((hi - ref.header.offsets) / ref.header.scales)
    a = ref.points.array
    keep = np.ones(len(a), bool)
    for i, c in enumerate("XYZ"):
        keep &= (a[c] >= mn[i]) & (a[c] <= mx[i])
    assert 0 < keep.sum() < len(a)
    assert np.array_equal(rows(got.array), rows(a[keep]))


def test_nodes_hold_their_points_and_the_hierarchy_is_consistent(written):
    _, copc, _ = written
    header, info, entries = node_entries(copc)
    with open(copc, "rb") as f:
        data = f.read()
    lz = header.vlrs.get("LasZipVlr")[0]
    import lazrs

    assert lazrs.LazVlr(lz.record_data).uses_variable_size_chunks()
    table_at = struct.unpack_from("<q", data, header.offset_to_point_data)[0]
    spans = sorted((off, off + size) for _, _, _, _, off, size, _ in entries)
    assert spans[0][0] == header.offset_to_point_data + 8 and spans[-1][1] == table_at
    assert all(a[1] == b[0] for a, b in zip(spans, spans[1:]))  # the chunks tile the point data exactly
    keys = {e[:4] for e in entries}
    assert (0, 0, 0, 0) in keys
    assert sum(e[6] for e in entries) == header.point_count
    side0 = 2 * info.halfsize
    mins = info.center - info.halfsize
    levels = set()
    for lv, x, y, z, off, size, count in entries:
        assert count > 0 and size > 0
        if lv:
            assert (lv - 1, x >> 1, y >> 1, z >> 1) in keys  # every node's parent exists
        levels.add(lv)
        pts = np.zeros(count * header.point_format.size, np.uint8)
        lazrs.decompress_points_with_chunk_table(data[off:off + size], lz.record_data, pts, [(count, size)])
        rec = laspy.PackedPointRecord.from_buffer(pts, header.point_format)
        w = np.column_stack([np.asarray(rec[c]) * header.scales[i] + header.offsets[i] for i, c in enumerate("XYZ")])
        side = side0 / 2 ** lv
        lo = mins + np.array([x, y, z]) * side
        eps = 1e-9 * side0
        assert np.all(w >= lo - eps) and np.all(w <= lo + side + eps), (lv, x, y, z)
        assert len(w) == count
    assert len(levels) >= 4
    assert info.spacing == pytest.approx(side0 / 4)


def test_node_cap_and_even_coarse_levels(written):
    _, copc, _ = written
    _, info, entries = node_entries(copc)
    with CopcReader.open(str(copc)) as r:
        deepest = max(e[0] for e in entries)
        for lv, x, y, z, *_rest, count in entries:
            has_children = any(e[0] == lv + 1 and (e[1] >> 1, e[2] >> 1, e[3] >> 1) == (x, y, z) for e in entries)
            if has_children:
                assert count <= 4 ** 3  # a sampled node: at most one point per cell of its 4^3 grid
            elif lv < deepest:
                assert count <= OPTS["node_points"]
        root = r.query(level=0)
    cells = np.floor((np.column_stack([root.x, root.y, root.z]) - (info.center - info.halfsize))
                     / info.spacing).astype(int)
    assert len(np.unique(cells, axis=0)) == len(cells)  # one point per occupied cell of the root's grid


def test_same_store_same_bytes_also_on_the_cluster(store, written, tmp_path, client):
    _, copc, _ = written
    write_copc(store, str(tmp_path / "again.copc.laz"), client=client, **OPTS)
    a, b = copc.read_bytes(), (tmp_path / "again.copc.laz").read_bytes()
    assert a == b


def test_defaults_make_one_group_and_names_are_checked(store, written, tmp_path):
    laz, _, _ = written
    rep = write_copc(store, str(tmp_path / "d.copc.laz"))
    assert rep["groups"] == 1 and rep["nodes"] >= 1
    with CopcReader.open(str(tmp_path / "d.copc.laz")) as r:
        assert len(r.query()) == rep["points"]
    with pytest.raises(UserError, match="ends in"):
        write_copc(store, str(tmp_path / "d.laz"))
    with pytest.raises(UserError, match="already exists"):
        write_copc(store, str(tmp_path / "d.copc.laz"))
    with pytest.raises(UserError, match="6, 7 and 8"):
        write_copc(store, str(tmp_path / "e.copc.laz"), point_format=3)
