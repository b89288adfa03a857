"""Ingesting the points inside a box: exactly those, in file order, from LAS and (by bounds) from COPC."""
from __future__ import annotations

import laspy
import numpy as np
import pytest
from laspy.copc import Bounds as CopcBounds
from laspy.copc import CopcReader

from tests.tiles.copcdata import OPTS, cloud, copc_store
from tiles.copc import EXTENSION, write_copc
from tiles.errors import UserError
from tiles.export import gather_points
from tiles.ingest import ingest
from tiles.ingest.bounds import Bounds
from tiles.ingest.las import LasReader

#: A box over part of the cloud (x 1000-1020, y 2000-2012), through its dense patch at (1001-1001.5, 2001-2001.5)
BOX = [1000.7, 2000.9, 1007.25, 2005.5]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("bounds")
    las = cloud(d / "plain.las")
    copc = d / ("c" + EXTENSION)
    write_copc(copc_store(d), str(copc), **OPTS)
    return d / "plain.las", copc, las


def _world(store):
    pts = gather_points(store, ["x", "y", "z"])
    m = store.meta
    return np.column_stack([pts[a] * m.scale[i] + m.offset[i] for i, a in enumerate("xyz")])


def _sorted(xyz):
    return xyz[np.lexsort(xyz.T[::-1])]


def _inside(x, y):
    return (x >= BOX[0]) & (x <= BOX[2]) & (y >= BOX[1]) & (y <= BOX[3])


def test_a_las_file_gives_exactly_its_points_inside_in_file_order(files, tmp_path):
    plain, _, las = files
    st = ingest([str(plain)], str(tmp_path / "s.zarr"), bounds=BOX, part_points=1000, tile_size=5.0)
    keep = _inside(np.asarray(las.x), np.asarray(las.y))
    assert 0 < keep.sum() < len(keep)
    np.testing.assert_allclose(_world(st), np.column_stack([las.x, las.y, las.z])[keep], atol=1e-9)
    assert st.ingest_report["outside"] == int((~keep).sum()) and st.ingest_report["bounds"] == BOX
    assert st.meta.sources[0].info["outside_bounds"] == int((~keep).sum())


def test_a_copc_file_is_read_by_bounds_and_gives_what_copc_reader_gives(files, tmp_path):
    _, copc, _ = files
    full = LasReader(str(copc))
    part = LasReader(str(copc))
    part.restrict(Bounds.parse(BOX))
    read = sum(s[2] for s in part.plan(1000))
    assert read < sum(s[2] for s in full.plan(1000))  # the nodes the box misses are not read
    st = ingest([str(copc)], str(tmp_path / "c.zarr"), bounds=BOX, part_points=1000, tile_size=5.0)
    with CopcReader.open(str(copc)) as r:
        z0, z1 = r.header.mins[2] - 1, r.header.maxs[2] + 1
        want = r.query(CopcBounds(np.array([BOX[0], BOX[1], z0]), np.array([BOX[2], BOX[3], z1])))
    got = _world(st)
    assert len(got) == len(want) > 0
    np.testing.assert_allclose(_sorted(got), _sorted(np.column_stack([want.x, want.y, want.z])), atol=1e-9)
    # in the file's order: the same as reading the whole file and keeping the points inside
    whole = laspy.read(str(copc))
    keep = _inside(np.asarray(whole.x), np.asarray(whole.y))
    np.testing.assert_allclose(got, np.column_stack([whole.x, whole.y, whole.z])[keep], atol=1e-9)
    assert st.ingest_report["outside"] == len(keep) - int(keep.sum())


def test_no_point_inside_and_bad_bounds_are_one_line_refusals(files, tmp_path):
    plain, _, _ = files
    with pytest.raises(UserError, match="no point inside the bounds"):
        ingest([str(plain)], str(tmp_path / "e.zarr"), bounds=[0, 0, 1, 1])
    assert not (tmp_path / "e.zarr").exists()
    for bad, why in (([1, 2, 3], "4 numbers"), ([5, 0, 1, 1], "below"), (["a", 0, 1, 1], "numbers"),
                     ([0, 0, float("inf"), 1], "finite")):
        with pytest.raises(UserError, match=why):
            Bounds.parse(bad)
