"""A space's points sorted by voxel: the points of a box, all of them or an even subsample."""
from __future__ import annotations

import numpy as np

from engine.detection import moments as mom
from engine.detection.pointindex import PointIndex


def _index(rng, n=20000):
    pts = rng.uniform(0, [3.0, 2.0, 2.5], (n, 3))
    grid = mom.VoxelGrid.covering(np.array([3.0, 2.0, 2.5]), 0.1, 10**6)
    return PointIndex(pts, grid), pts


def test_a_box_gives_every_point_inside_it():
    rng = np.random.default_rng(0)
    index, pts = _index(rng)
    lo, hi = np.array([0.42, 0.3, 1.0]), np.array([1.77, 1.2, 2.05])
    got = index.points_in_metric(lo, hi)
    inside = np.all((pts >= lo) & (pts <= hi), axis=1)
    got_inside = np.all((got >= lo) & (got <= hi), axis=1)
    assert got_inside.sum() == inside.sum() > 100  # a superset of the box's points, each once
    assert len(np.unique(got, axis=0)) == len(got)


def test_at_most_takes_every_nth_point_before_gathering():
    rng = np.random.default_rng(1)
    index, _ = _index(rng)
    lo, hi = np.array([0.2, 0.1, 0.3]), np.array([2.6, 1.9, 2.2])
    every = index.points_in_metric(lo, hi)
    for at_most in (50, 999, 4321, len(every) - 1):
        some = index.points_in_metric(lo, hi, at_most)
        step = -(-len(every) // at_most)
        assert np.array_equal(some, every[::step]) and len(some) <= at_most
    assert np.array_equal(index.points_in_metric(lo, hi, len(every)), every)
    # runs of empty voxels between full ones do not shift the ranks
    sparse_index, _ = _index(rng, n=300)
    a = sparse_index.points_in_metric(np.zeros(3), np.array([3.0, 2.0, 2.5]))
    assert np.array_equal(sparse_index.points_in_metric(np.zeros(3), np.array([3.0, 2.0, 2.5]), 7), a[::-(-len(a) // 7)])
