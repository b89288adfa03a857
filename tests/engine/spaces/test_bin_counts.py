"""A tile's points counted per (u, v, storey, band) bin: every point once, and passes over them exact."""
from __future__ import annotations

import pickle

import numpy as np
import pytest

from engine.spaces import bin_counts
from engine.spaces.alignment import Frame
from engine.spaces.bin_counts import CountedStore, count_tile
from engine.spaces.histograms import BoxIndex, EdgeTables, Grid, edge_histograms, keyed_histogram, segment_histograms
from engine.spaces.memory_store import MemoryStore

ORIGIN = (1005.0, 2003.0, 10.0)
FLOORS = np.array([[0, 150], [150, 300]])
BAND_Z = np.array([110, 260])


def _store(seed: int = 0, n: int = 20000) -> tuple[MemoryStore, Grid]:
    """Points on a few walls (many per 1 cm column) and scattered points, over two storeys and beyond."""
    rng = np.random.default_rng(seed)
    x = np.concatenate([rng.integers(5000, 5040, n // 2), rng.integers(0, 8000, n - n // 2)])
    y = np.concatenate([rng.integers(3000, 3300, n // 2), rng.integers(0, 6000, n - n // 2)])
    z = rng.integers(-500, 6500, n)  # 1 mm units; bins of 2 cm: -25 ... 325 (below, in and above the storeys)
    raw = {"x": x.astype(np.int32), "y": y.astype(np.int32), "z": z.astype(np.int32)}
    mem = MemoryStore(raw, (0.001, 0.001, 0.001), (1000.0, 2000.0, 10.0), ORIGIN)
    return mem, Grid.for_store(mem, Frame(0.3, ORIGIN), 0.01, 0.02)


def _storeys() -> BoxIndex:
    return BoxIndex.build(FLOORS, np.zeros((0, 5), np.int64))


def test_every_point_is_counted_once_in_its_bin():
    mem, grid = _store()
    t = count_tile("memory", mem, grid, _storeys(), BAND_Z)
    bu, bv, bz = grid.tile_bins(mem, "memory")
    f = _storeys().storey_rows(bz)
    band = (bz >= np.append(BAND_Z, np.iinfo(np.int64).max)[f]).astype(np.int64)
    keys, count = np.unique(np.stack([bu, bv, f, band], axis=1), axis=0, return_counts=True)
    got = np.stack([t.bu, t.bv, t.storey, t.band], axis=1).astype(np.int64)
    np.testing.assert_array_equal(got, keys)  # sorted by (u, v, storey, band), each combination once
    np.testing.assert_array_equal(t.count, count)
    assert t.points == mem.meta.point_count and len(t.count) < 0.6 * mem.meta.point_count  # the wall collapses
    assert set(np.unique(t.storey).tolist()) == {0, 1, 2}  # 2: in no storey


def test_counting_by_sorting_gives_the_same_counts(monkeypatch):
    mem, grid = _store(1)
    dense = count_tile("memory", mem, grid, _storeys(), BAND_Z)
    monkeypatch.setattr(bin_counts, "DENSE_MAX", 0)
    sorted_ = count_tile("memory", mem, grid, _storeys(), BAND_Z)
    for a in ("bu", "bv", "storey", "band", "count"):
        np.testing.assert_array_equal(getattr(dense, a), getattr(sorted_, a))


def test_a_weighted_keyed_histogram_equals_repeating_the_entries():
    rng = np.random.default_rng(4)
    seg, b, w = rng.integers(-1, 5, 3000), rng.integers(-30, 70, 3000), rng.integers(1, 9, 3000)
    got = keyed_histogram(seg, b, w)
    want = keyed_histogram(np.repeat(seg, w), np.repeat(b, w))
    assert got.counts.dtype == np.int64 and got.lo == want.lo
    np.testing.assert_array_equal(got.segments, want.segments)
    np.testing.assert_array_equal(got.counts, want.counts)


def _same(a, b) -> None:
    np.testing.assert_array_equal(a.segments, b.segments)
    assert a.lo == b.lo
    np.testing.assert_array_equal(a.counts, b.counts)


def test_passes_over_the_counts_equal_passes_over_the_points():
    mem, grid = _store(2)
    bu, bv, _ = grid.tile_bins(mem, "memory")
    um, vm = int(np.median(bu)), int(np.median(bv))
    boxes = np.array([[0, bu.min(), um, bv.min(), bv.max() + 1], [0, um, bu.max() + 1, bv.min(), vm],
                      [1, bu.min(), bu.max() + 1, bv.min(), vm], [1, bu.min(), bu.max() + 1, vm, bv.max() + 1]])
    index = BoxIndex.build(FLOORS, boxes)
    counted = CountedStore(mem, grid, _storeys(), BAND_Z)
    args = (grid, index, np.array([0, 1, -1, 0]), np.array([True, False, False, True]), BAND_Z)
    _same(segment_histograms("memory", counted, *args), segment_histograms("memory", mem, *args))
    rng = np.random.default_rng(5)
    n_blocks = len(index.flat) - 1
    tables = EdgeTables(rng.integers(-1, 6, 4 * n_blocks + 4), np.array([0, 1, 0, 1, 0, 1]),
                        np.array([um, vm, um + 40, vm - 30, um - 300, vm + 200]), 80)
    _same(edge_histograms("memory", counted, grid, index, tables, BAND_Z),
          edge_histograms("memory", mem, grid, index, tables, BAND_Z))


def test_counts_made_for_other_storeys_are_refused():
    mem, grid = _store(3)
    t = count_tile("memory", mem, grid, _storeys(), BAND_Z)
    t.check(grid, _storeys(), BAND_Z)
    with pytest.raises(ValueError, match="other storeys"):
        t.check(grid, _storeys(), BAND_Z + 1)
    with pytest.raises(ValueError, match="other storeys"):
        t.check(grid, BoxIndex.build(FLOORS[:1], np.zeros((0, 5), np.int64)), BAND_Z)
    turned = Grid.for_store(mem, Frame(0.4, ORIGIN), 0.01, 0.02)
    with pytest.raises(ValueError, match="grid"):
        t.check(turned, _storeys(), BAND_Z)


def test_a_counted_store_keeps_its_counts_and_pickles_without_them():
    mem, grid = _store(4)
    counted = CountedStore(mem, grid, _storeys(), BAND_Z)
    assert counted.counted("memory") is counted.counted("memory")  # made once, kept for the next pass
    assert counted.tiles == mem.tiles and counted.meta is mem.meta
    copy = pickle.loads(pickle.dumps(counted))
    assert copy._kept == {} and copy._futures == {}
    counted.release()
    assert counted._kept == {}
