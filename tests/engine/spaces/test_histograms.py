"""Per-tile keyed histograms: one bincount per tile equals per-segment counting, and tiles sum exactly."""
from __future__ import annotations

import numpy as np

from engine.spaces.histograms import BoxIndex, accumulate, keyed_histogram, upper_band


def test_keyed_histogram_equals_counting_each_segment():
    rng = np.random.default_rng(0)
    seg = rng.integers(-1, 7, 5000)
    b = rng.integers(-40, 60, 5000)
    sh = keyed_histogram(seg, b)
    assert sh.segments.tolist() == sorted(set(seg[seg >= 0].tolist()))
    for k, s in enumerate(sh.segments):
        expected = np.bincount(b[seg == s] - sh.lo, minlength=sh.counts.shape[1])
        np.testing.assert_array_equal(sh.counts[k], expected)
    assert sh.counts.sum() == (seg >= 0).sum()


def test_accumulate_over_tiles_equals_the_whole():
    rng = np.random.default_rng(1)
    seg = rng.integers(0, 4, 9000)
    b = rng.integers(0, 300, 9000)
    lo = np.array([0, 50, 100, 0])
    length = np.array([300, 250, 200, 300])
    keep = b >= lo[seg]
    seg, b = seg[keep], b[keep]
    parts = [keyed_histogram(seg[i:i + 1000], b[i:i + 1000]) for i in range(0, len(seg), 1000)]
    hists = accumulate(parts, lo, length)
    for s in range(4):
        np.testing.assert_array_equal(hists[s], np.bincount(b[seg == s] - lo[s], minlength=length[s]))


def test_box_index_locates_points_like_brute_force():
    rng = np.random.default_rng(2)
    # a k-d partition of two storeys, with a hole (a box left out: points there are in no box)
    boxes = np.array([[0, 0, 50, 0, 40], [0, 50, 120, 0, 25], [0, 50, 90, 25, 40], [0, 90, 120, 25, 40],
                      [1, -10, 30, -5, 60], [1, 30, 100, -5, 60]])
    floors = np.array([[0, 100], [150, 260]])
    index = BoxIndex.build(floors, np.delete(boxes, 2, axis=0))
    n = 20000
    bu, bv, bz = rng.integers(-20, 130, n), rng.integers(-10, 70, n), rng.integers(-10, 300, n)
    got = index.locate(bu, bv, bz)
    kept = np.delete(boxes, 2, axis=0)
    expected = np.full(n, -1)
    for k, (f, u0, u1, v0, v1) in enumerate(kept):
        z0, z1 = floors[f]
        inside = (bz >= z0) & (bz < z1) & (bu >= u0) & (bu < u1) & (bv >= v0) & (bv < v1)
        assert np.all(expected[inside] == -1)  # disjoint boxes
        expected[inside] = k
    np.testing.assert_array_equal(got, expected)


def test_upper_band_is_relative_to_each_storey():
    floor = np.array([0, 0, 1, 1, -1])
    bz = np.array([100, 250, 300, 500, 900])
    np.testing.assert_array_equal(upper_band(floor, bz, np.array([200, 450])), [0, 1, 0, 1, 1])
