"""The store builder: parts staged by tile, tiles written whole by one task each, nothing lost."""
from __future__ import annotations

import numpy as np
import pytest

from tiles.builder import StoreBuilder
from tiles.errors import UserError
from tiles.schema import Dimension, Part, Source, coordinate_dimensions
from tiles.store import open_store
from tiles.tasks import run_tasks


def _cloud(n=50_000, seed=0):
    rng = np.random.default_rng(seed)
    xyz = rng.uniform([0, 0, 0], [37.0, 23.0, 3.0], size=(n, 3))
    raw = np.round((xyz - [1000.0, 2000.0, 0.0] + [1000.0, 2000.0, 0.0]) / 0.001).astype(np.int32)
    return {"x": raw[:, 0], "y": raw[:, 1], "z": raw[:, 2],
            "intensity": rng.integers(0, 65535, n).astype(np.uint16),
            "red": rng.integers(0, 255, n).astype(np.uint16)}


DIMS = coordinate_dimensions() + [Dimension("intensity", "uint16", "las", las={"name": "intensity"}),
                                  Dimension("red", "uint16", "las", las={"name": "red"})]


def _stage(bounds, builder, cols):
    return builder.write_part(bounds[0], {k: v[bounds[1]:bounds[2]] for k, v in cols.items()})


def _build(path, cols, n_parts, client=None, tile_size=10.0):
    n = len(cols["x"])
    edges = np.linspace(0, n, n_parts + 1).astype(int)
    parts = [Part(0, int(a), int(b - a)) for a, b in zip(edges[:-1], edges[1:])]
    b = StoreBuilder.create(str(path), dimensions=DIMS, scale=[0.001] * 3, offset=[0.0, 0.0, 0.0],
                            tile_size=tile_size)
    jobs = [(k, int(a), int(b_)) for k, (a, b_) in enumerate(zip(edges[:-1], edges[1:]))]
    summaries = run_tasks(_stage, jobs, client=client, extra_args=(b, cols))
    return b.finalize(summaries, parts=parts, sources=[Source("mem", "test", n)], client=client)


def _gather(store):
    """All points back in input order, from the tiles."""
    cols = {}
    pieces = {c: [] for c in ("x", "y", "z", "intensity", "red", "point_index")}
    for t in store.tiles:
        for c, v in store.read(t, pieces).items():
            pieces[c].append(v)
    cols = {c: np.concatenate(v) for c, v in pieces.items()}
    order = np.argsort(cols.pop("point_index"))
    return {c: v[order] for c, v in cols.items()}


def test_many_parts_on_cluster_equal_one_part(tmp_path, client):
    cols = _cloud()
    one = _build(tmp_path / "one.zarr", cols, 1)
    many = _build(tmp_path / "many.zarr", cols, 13, client=client)
    assert one.meta.point_count == many.meta.point_count == len(cols["x"])
    assert [t.name for t in one.tiles] == [t.name for t in many.tiles]
    for t1, t2 in zip(one.tiles, many.tiles):
        a = one.read(t1, ["x", "y", "z", "intensity", "point_index"])
        b = many.read(t2, ["x", "y", "z", "intensity", "point_index"])
        for k in a:
            np.testing.assert_array_equal(a[k], b[k])
    back = _gather(many)
    for k in ("x", "y", "z", "intensity", "red"):
        np.testing.assert_array_equal(back[k], cols[k])


def test_tiles_hold_their_points_in_input_order(tmp_path):
    cols = _cloud(20_000, seed=3)
    store = _build(tmp_path / "s.zarr", cols, 4)
    assert len(store.tiles) == 4 * 3  # 37 x 23 m at 10 m tiles
    for t in store.tiles:
        pi = store.read(t, ["point_index"])["point_index"]
        assert np.all(np.diff(pi) > 0)
        xyz = store.xyz(t, local=False)
        assert np.all(np.floor(xyz[:, 0] / 10) == t.ix) and np.all(np.floor(xyz[:, 1] / 10) == t.iy)
        offs = store.part_offsets(t)
        assert offs[-1] == t.count and len(offs) == 5


def test_existing_target_refused_and_nothing_left_on_failure(tmp_path):
    cols = _cloud(1000)
    _build(tmp_path / "s.zarr", cols, 1)
    with pytest.raises(UserError, match="already exists"):
        StoreBuilder.create(str(tmp_path / "s.zarr"), dimensions=DIMS, scale=[0.001] * 3, offset=[0, 0, 0])
    b = StoreBuilder.create(str(tmp_path / "t.zarr"), dimensions=DIMS, scale=[0.001] * 3, offset=[0, 0, 0])
    b.write_part(0, {k: v[:10] for k, v in cols.items()})
    b.abort()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.zarr"]


def test_unfinished_store_is_refused(tmp_path):
    b = StoreBuilder.create(str(tmp_path / "t.zarr"), dimensions=DIMS, scale=[0.001] * 3, offset=[0, 0, 0])
    with pytest.raises(UserError, match="incomplete"):
        open_store(b.build_url)


def test_constant_arrays_are_not_staged_and_keep_every_bit(tmp_path):
    """A dimension constant in a part is kept in the part's summary, not staged; its bits come back exactly
    (-0.0 and a NaN payload included), next to parts where the same dimension varies."""
    n = 6000
    cols = _cloud(n, seed=5)
    odd_nan = np.array([0x7FF8DEADBEEF0001], dtype=np.uint64).view(np.float64)[0]
    gps = np.concatenate([np.full(2000, -0.0), np.full(2000, odd_nan), np.linspace(-1, 1, 2000)])
    flag = np.concatenate([np.full(4000, 7, np.uint8), np.arange(2000) % 3]).astype(np.uint8)
    cols = {**cols, "gps_time": gps, "flag": flag}
    dims = DIMS + [Dimension("gps_time", "float64", "las", las={"name": "gps_time"}),
                   Dimension("flag", "uint8", "las", las={"name": "user_data"})]
    b = StoreBuilder.create(str(tmp_path / "c.zarr"), dimensions=dims, scale=[0.001] * 3, offset=[0.0] * 3)
    summaries = [b.write_part(k, {c: v[2000 * k:2000 * (k + 1)] for c, v in cols.items()}) for k in range(3)]
    assert set(summaries[0].constants) == {"gps_time", "flag"} and set(summaries[1].constants) == {"gps_time", "flag"}
    assert summaries[2].constants == {}
    store = b.finalize(summaries, parts=[Part(0, 2000 * k, 2000) for k in range(3)],
                       sources=[Source("mem", "test", n)])
    pieces = {c: [] for c in ("gps_time", "flag", "x", "point_index")}
    for t in store.tiles:
        for c, v in store.read(t, list(pieces)).items():
            pieces[c].append(v)
    back = {c: np.concatenate(v) for c, v in pieces.items()}
    order = np.argsort(back["point_index"])
    np.testing.assert_array_equal(back["gps_time"][order].view(np.uint64), gps.view(np.uint64))
    np.testing.assert_array_equal(back["flag"][order], flag)
    np.testing.assert_array_equal(back["x"][order], cols["x"])


@pytest.mark.parametrize("scale,offset,tile,span", [
    (0.001, 0.0, 10.0, 40_000), (0.0005, 500_000.0, 10.0, 150_000), (0.0003, -12.345, 7.0, 90_000),
    (0.01, 4_000_000.0, 10.0, 5_000), (0.001, 0.0, 0.25, 3_000), (0.0001, 123.0, 20.0, 10),
    (0.001, 0.0, 0.001, 9_000)])
def test_local_tile_index_equals_the_float_formula(tmp_path, scale, offset, tile, span):
    """The integer shortcut gives exactly the tile of ``floor((raw * scale + offset) / tile)``, also on and
    next to every tile boundary and for parts that do not start on one."""
    b = StoreBuilder.create(str(tmp_path / "k.zarr"), dimensions=DIMS, scale=[scale] * 3,
                            offset=[offset] * 3, tile_size=tile)
    rng = np.random.default_rng(int(span))
    base = int(rng.integers(-10 ** 6, 10 ** 6))
    raw = base + rng.integers(0, span, 20_000)
    # every raw value within 2 steps of each tile boundary of the range
    ks = np.arange(np.floor((raw.min() * scale + offset) / tile), np.floor((raw.max() * scale + offset) / tile) + 2)
    near = np.round((ks * tile - offset) / scale).astype(np.int64)[:, None] + np.arange(-2, 3)
    raw = np.concatenate([raw, near.ravel()]).astype(np.int32)
    expect, _ = b.tile_keys(raw, raw)
    idx, first, count = b.local_tile_index(raw, 0)
    np.testing.assert_array_equal(idx.astype(np.int64) + first, expect)
    assert first == expect.min() and count == expect.max() - expect.min() + 1


def _staged_bytes(builder, part_id):
    import os

    from tiles.staging import staging_url
    return os.path.getsize(staging_url(builder.build_url, part_id))


def test_staged_runs_are_compressed_and_come_back_exactly(tmp_path):
    """A part's staging file holds its tile runs compressed (a smooth cloud: well under its raw bytes), and the
    tiles built from it hold every value and the input order."""
    n = 40_000
    cols = _cloud(n, seed=7)
    cols["intensity"] = (np.arange(n) % 50).astype(np.uint16)  # compressible
    b = StoreBuilder.create(str(tmp_path / "z.zarr"), dimensions=DIMS, scale=[0.001] * 3, offset=[0.0] * 3)
    s = b.write_part(0, cols)
    raw = sum(np.dtype(dt).itemsize * n for _, dt in b.staging_layout(n, s.constants))
    assert _staged_bytes(b, 0) == sum(sum(r[4]) for r in s.tiles.values()) < 0.8 * raw
    assert sum(r[0] for r in s.tiles.values()) == n
    store = b.finalize([s], parts=[Part(0, 0, n)], sources=[Source("mem", "test", n)])
    back = _gather(store)
    for k in ("x", "y", "z", "intensity", "red"):
        np.testing.assert_array_equal(back[k], cols[k])


def test_runs_larger_than_a_piece_are_cut_and_put_back_together(tmp_path, monkeypatch):
    """Blosc takes at most 2 GB at once: a run's array larger than ``STAGING_PIECE`` is staged in pieces.  With
    pieces of 64 bytes the store equals the one staged whole."""
    from tiles import staging

    cols = _cloud(9_000, seed=8)
    whole = _build(tmp_path / "whole.zarr", cols, 3)
    monkeypatch.setattr(staging, "STAGING_PIECE", 64)
    cut = _build(tmp_path / "cut.zarr", cols, 3)
    assert [t.name for t in whole.tiles] == [t.name for t in cut.tiles]
    for t1, t2 in zip(whole.tiles, cut.tiles):
        a = whole.read(t1, ["x", "y", "z", "intensity", "red", "point_index"])
        b = cut.read(t2, ["x", "y", "z", "intensity", "red", "point_index"])
        for k in a:
            np.testing.assert_array_equal(a[k], b[k])
