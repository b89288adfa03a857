"""Ingest memory is bounded by the part and tile sizes, not by the file: a file three times
larger (same density, three times the area) ingests with the same peak of traced allocations.

This is what lets a file larger than memory ingest: each task holds one part (or one tile),
never the file.  numpy reports its buffers to ``tracemalloc``, so the peak below counts every
decoded record, column, sort and staging buffer of the in-process (client-less) ingest.
"""
from __future__ import annotations

import tracemalloc

import laspy
import numpy as np

from tiles.ingest import ingest

DENSITY = 1000.0  # points per m^2 of XY
PART = 100_000
TILE = 5.0


def _write_laz(path, length_m: float, seed: int) -> int:
    rng = np.random.default_rng(seed)
    n = int(length_m * 20.0 * DENSITY)
    las = laspy.LasData(laspy.LasHeader(point_format=7, version="1.4"))
    las.header.scales = np.array([0.001] * 3)
    las.header.offsets = np.zeros(3)
    xyz = rng.uniform([0, 0, 0], [length_m, 20.0, 3.0], (n, 3))
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    for c in ("red", "green", "blue", "intensity"):
        setattr(las, c, rng.integers(0, 65535, n).astype(np.uint16))
    las.write(str(path))
    return n


def _peak_ingest(src, store) -> tuple[int, int]:
    tracemalloc.start()
    try:
        out = ingest(str(src), str(store), part_points=PART, tile_size=TILE)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return out.meta.point_count, peak


def test_peak_memory_does_not_grow_with_the_file(tmp_path):
    n_small = _write_laz(tmp_path / "small.laz", 40.0, 1)
    n_large = _write_laz(tmp_path / "large.laz", 120.0, 2)
    _peak_ingest(tmp_path / "small.laz", tmp_path / "warm.zarr")  # first-use buffers and imports
    count_s, peak_s = _peak_ingest(tmp_path / "small.laz", tmp_path / "small.zarr")
    count_l, peak_l = _peak_ingest(tmp_path / "large.laz", tmp_path / "large.zarr")
    assert (count_s, count_l) == (n_small, n_large)
    decoded_large = n_large * (3 * 8 + 4 * 2)  # x, y, z as float64 and four uint16 columns
    # the whole large file decoded would be ~77 MB; ingest holds a part or a tile at a time
    assert peak_l < decoded_large / 4, (peak_l, decoded_large)
    assert peak_l < 1.3 * peak_s + 4e6, (peak_s, peak_l)
