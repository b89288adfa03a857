"""Surfaces in a space's detections: a thin box moved onto its surface, its extent fitted, the one ceiling and floor."""
from __future__ import annotations

import numpy as np

from engine.detection.surfaces import expected_extreme, refine_extent, surface_order, surface_shift


def test_surface_shift_moves_a_thin_box_onto_the_surface_beside_it():
    rng = np.random.default_rng(0)
    vox, bin_ = 0.1, 0.005
    # a ceiling at z = 3.03 (voxel 30) over beam sides spread evenly through voxels 26-30
    ceiling = 3.03 + rng.normal(0, 0.003, 5000)
    beams = rng.uniform(2.6, 3.03, 2000)
    values = np.concatenate([ceiling, beams])
    sel = lambda a, b: values[(values >= a * vox) & (values < b * vox)]  # noqa: E731
    # the best window was the beams' layer, voxel 29; NMS grew it by one voxel each way
    assert surface_shift(sel(28, 31), 29, 30, 28, 31, vox, bin_) == 1
    assert surface_shift(sel(29, 32), 30, 31, 29, 32, vox, bin_) == 0  # already on it
    assert surface_shift(sel(26, 29), 27, 28, 26, 29, vox, bin_) == 0  # no surface in reach: stays
    assert surface_shift(sel(29, 32), 31, 32, 29, 32, vox, bin_) == -1  # from above
    assert surface_shift(sel(27, 31), 28, 30, 27, 31, vox, bin_) == 1  # a box two voxels thick: the smallest move
    assert surface_shift(np.zeros(0), 3, 4, 2, 5, vox, bin_) == 0


def test_refine_extent_is_the_noise_band_of_the_surface():
    rng = np.random.default_rng(1)
    sigma = 0.004
    wall = 1.234 + rng.normal(0, sigma, 20000)
    # a board's edge and a few stray points touching the wall widen the dense run, not the band
    stray = np.concatenate([rng.uniform(1.25, 1.27, 600), rng.uniform(1.2, 1.3, 100)])
    lo, hi = refine_extent(np.concatenate([wall, stray]), 1.2, 1.3, 0.005)
    assert abs((lo + hi) / 2 - 1.234) < 0.002
    assert 5 * sigma < hi - lo < 7 * sigma  # +- 3 sigma: the band holding the surface's points
    # tightest: the span the surface's own points have (S3DIS's box), still without the strays
    lo, hi = refine_extent(np.concatenate([wall, stray]), 1.2, 1.3, 0.005, sigmas=None)
    assert abs((hi - lo) - np.ptp(wall)) < 0.5 * sigma
    assert hi < 1.25
    # a noise-free plane still gets a box (one bin), and no points leave the box as it was
    lo, hi = refine_extent(np.full(50, 1.234), 1.2, 1.3, 0.005)
    assert lo < 1.234 < hi and 0.002 < hi - lo <= 0.005
    assert refine_extent(np.zeros(0), 1.2, 1.3, 0.005) == (1.2, 1.3)


def test_a_spaces_one_ceiling_is_its_highest_window_and_its_floor_its_lowest():
    """``surface-choice``: a table-top plane or a beam's underside that outscores the ceiling is not the ceiling."""

    keep = np.array([4, 0, 2, 3])  # best first: a plane at 0.9 m, the ceiling, a window at mid-height, the floor
    lo = np.zeros((5, 3), dtype=np.int64)
    hi = np.ones((5, 3), dtype=np.int64)
    lo[4, 2], hi[4, 2] = 9, 10  # middle 0.95 m in a 3 m (30 voxel) space
    lo[0, 2], hi[0, 2] = 29, 30
    lo[2, 2], hi[2, 2] = 14, 16  # middle exactly half-way: in both halves
    lo[3, 2], hi[3, 2] = 0, 1
    assert surface_order(keep, lo, hi, 30, upper=True)[0] == 0
    assert surface_order(keep, lo, hi, 30, upper=False)[0] == 3
    assert surface_order(keep, lo, hi, 30, True, "halves").tolist() == [0, 2]
    assert surface_order(keep, lo, hi, 30, False, "halves").tolist() == [4, 2, 3]
    assert surface_order(np.array([4]), lo, hi, 30, True, "halves").tolist() == [4]  # nothing above: what there is
    assert surface_order(keep, lo, hi, 30, True, "score").tolist() == keep.tolist()
    ties = np.array([2, 1])  # same height: the better score first
    lo[1], hi[1] = lo[2], hi[2]
    assert surface_order(ties, lo, hi, 30, upper=True).tolist() == [2, 1]


def test_expected_extreme_is_the_mean_largest_of_n_normals():
    rng = np.random.default_rng(2)
    for n in (30, 1000, 20000):
        mean_max = rng.normal(size=(200, n)).max(axis=1).mean()
        assert abs(expected_extreme(n) - mean_max) < 0.1
    assert expected_extreme(0) == expected_extreme(1) == 1.0
