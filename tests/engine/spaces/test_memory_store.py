"""The store in memory of a refined space's points: the bins of its real coordinates, kept once per grid."""
from __future__ import annotations

import math

import numpy as np

from engine.spaces.alignment import Frame
from engine.spaces.histograms import Grid
from engine.spaces.memory_store import MemoryStore


def test_memory_store_gives_the_bins_of_the_real_coordinates():
    rng = np.random.default_rng(2)
    scale, offset, origin = (0.001, 0.001, 0.001), (1000.0, 2000.0, 10.0), (1005.0, 2003.0, 10.0)
    raw = {a: rng.integers(0, 20000, 500).astype(np.int32) for a in "xyz"}
    mem = MemoryStore(raw, scale, offset, origin)
    assert mem.meta.point_count == 500 and mem.tiles[0].count == 500
    xy = mem.xy_local()
    assert np.allclose(xy[:, 0], raw["x"] * 0.001 + 1000.0 - 1005.0)
    grid = Grid.for_store(mem, Frame(0.3, origin), 0.01, 0.02)
    bu, bv, bz = grid.tile_bins(mem, "memory")
    u = math.cos(0.3) * xy[:, 0] + math.sin(0.3) * xy[:, 1]
    assert np.mean(bu == np.floor(u / 0.01)) > 0.99  # floating rounding at bin edges aside


def test_memory_store_computes_the_bins_once_per_grid():
    """The refinement's passes share one copy of the bins (read-only) instead of computing them per pass."""
    rng = np.random.default_rng(3)
    origin = (1005.0, 2003.0, 10.0)
    raw = {a: rng.integers(0, 20000, 500).astype(np.int32) for a in "xyz"}
    mem = MemoryStore(raw, (0.001, 0.001, 0.001), (1000.0, 2000.0, 10.0), origin)
    grid = Grid.for_store(mem, Frame(0.3, origin), 0.01, 0.02)
    first = grid.tile_bins(mem, "memory")
    assert grid.tile_bins(mem, "memory") is first  # the same arrays, not computed again
    plain = grid.raw_bins(raw, grid.raw_affine(mem.meta))
    assert all(np.array_equal(a, b) and not a.flags.writeable for a, b in zip(first, plain))
    other = Grid.for_store(mem, Frame(0.5, origin), 0.01, 0.02)  # another frame: computed for it
    turned = other.tile_bins(mem, "memory")
    assert turned is not first and np.array_equal(turned[0], other.raw_bins(raw, other.raw_affine(mem.meta))[0])
