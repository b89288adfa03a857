"""Table 1 features from summed voxel moments: hand-made patterns give what they should."""
from __future__ import annotations

import numpy as np
import pytest

from engine.detection import moments as mom
from engine.detection.canonical import CanonicalFrame
from engine.detection.features import window_features
from engine.detection.global_block import global_features
from engine.detection.layout import FeatureLayout
from engine.detection.sliding import score_windows
from engine.detection.volume import SpaceVolume


def _volume(xyz, rgb=None, extent=(2.0, 2.0, 2.0), voxel=0.1, yaw=0.0):
    frame = CanonicalFrame(yaw, [0.0, 0.0, 0.0], extent)
    return SpaceVolume.build(frame.from_metric(xyz), rgb, frame, voxel, 10**7)


def _local(layout, feats):
    """The local block of one window as (K, K, K, 9)."""
    k = layout.k
    return feats[layout.n_global:layout.local_end].reshape(k, k, k, -1)


def test_integral_volume_box_sums_equal_brute_force():
    rng = np.random.default_rng(0)
    xyz = rng.uniform(0, [2, 1.5, 1], (5000, 3))
    rgb = rng.uniform(0, 1, (5000, 3))
    grid = mom.VoxelGrid.covering([2, 1.5, 1], 0.1, 10**6)
    iv = mom.integral_volume(mom.voxel_moments(xyz, rgb, grid))
    lo, hi = np.array([3, 2, 1]), np.array([11, 9, 7])
    inside = np.all((xyz >= lo * grid.voxel) & (xyz < hi * grid.voxel), axis=1)
    s = mom.box_sums(iv, lo, hi)
    p = xyz[inside] - grid.center
    assert s[0] == inside.sum()
    assert np.allclose(s[1:4], p.sum(0))
    assert np.allclose(s[4], (p[:, 0] ** 2).sum()) and np.allclose(s[8], (p[:, 1] * p[:, 2]).sum())
    assert np.allclose(s[10:], rgb[inside].sum(0))
    grid_sums = mom.box_sums_grid(iv, np.array([[3, 11]]), np.array([[2, 9]]), np.array([[1, 7]]))
    assert np.allclose(grid_sums[0, 0, 0], s)


def test_flat_wall_patch_gives_its_normal_and_no_curvature():
    rng = np.random.default_rng(1)
    n = 20000
    # a wall patch: the plane y = 0.73, 0.4 .. 1.6 in x and z, 1 mm noise, one colour
    xyz = np.c_[rng.uniform(0.4, 1.6, n), 0.73 + rng.normal(0, 0.001, n), rng.uniform(0.4, 1.6, n)]
    rgb = np.tile([0.2, 0.5, 0.9], (n, 1))
    vol = _volume(xyz, rgb)
    lay = FeatureLayout(k=3)
    f = window_features(vol.iv, vol.grid, np.array([[4, 6, 4]]), np.array([[16, 9, 16]]), lay)[0]
    loc = _local(lay, f)
    # the plane passes through the middle slab of sub-boxes along y only
    occ = loc[..., 0]
    assert occ[:, 1, :].all() and not occ[:, 0, :].any() and not occ[:, 2, :].any()
    full = loc[:, 1, :]
    assert np.allclose(full[..., 5:8], [0, 1, 0], atol=1e-3)  # |normal| = y
    assert np.all(full[..., 8] < 1e-4)  # curvature
    assert np.allclose(full[..., 2:5], [0.2, 0.5, 0.9])  # mean colour
    assert np.isclose(loc[..., 1].sum(), 27)  # ratios sum to 1, scaled by K^3
    assert np.allclose(full[..., 1], 27 / 9, rtol=0.1)  # even spread over the 9 occupied sub-boxes
    # empty sub-boxes are all zero
    assert np.all(loc[:, 0, :] == 0)


def test_hand_made_voxel_pattern():
    # points in two opposite corner voxels of a 4 x 4 x 4 voxel window, 3 and 1 points
    pts = np.array([[0.05, 0.05, 0.05]] * 3 + [[0.35, 0.35, 0.35]])
    vol = _volume(pts, None, extent=(0.4, 0.4, 0.4))
    lay = FeatureLayout(k=2)
    f = window_features(vol.iv, vol.grid, np.array([[0, 0, 0]]), np.array([[4, 4, 4]]), lay)[0]
    loc = _local(lay, f)
    expected_occ = np.zeros((2, 2, 2))
    expected_occ[0, 0, 0] = expected_occ[1, 1, 1] = 1
    assert np.array_equal(loc[..., 0], expected_occ)
    assert loc[0, 0, 0, 1] == pytest.approx(3 / 4 * 8) and loc[1, 1, 1, 1] == pytest.approx(1 / 4 * 8)
    assert np.all(loc[..., 5:] == 0)  # fewer than 3 distinct points: no normal, no curvature
    # global features: P = 0, S = 1, sizes 0.4 m
    g = f[:lay.n_global]
    assert np.allclose(g[:3], 0) and np.allclose(g[18:21], 1)
    assert np.allclose(g, global_features(np.zeros(3), np.ones(3), np.full(3, 0.4), np.full(3, 0.4)))
    assert np.allclose(g[-15:].reshape(3, 5), [1, 0, 0, 0, 0])  # against both ends: distance 0


def test_min_points_and_disabled_groups():
    pts = np.array([[0.05, 0.05, 0.05]] * 3 + [[0.35, 0.35, 0.35]])
    vol = _volume(pts, np.ones((4, 3)), extent=(0.4, 0.4, 0.4))
    lay = FeatureLayout(k=2, min_points=2, disabled=("color", "position"))
    f = window_features(vol.iv, vol.grid, np.array([[0, 0, 0]]), np.array([[4, 4, 4]]), lay)[0]
    loc = _local(lay, f)
    assert loc[0, 0, 0, 0] == 1 and loc[1, 1, 1, 0] == 0  # one point is not enough
    assert np.all(loc[..., 2:5] == 0) and np.all(f[:3] == 0)
    with pytest.raises(ValueError):
        FeatureLayout(k=2, disabled=("nonsense",))
    assert FeatureLayout.from_json(lay.to_json()).mask.tolist() == lay.mask.tolist()


@pytest.mark.parametrize("shape", [[7, 5, 9], [20, 2, 15], [1, 1, 1], [20, 20, 20], [3, 11, 4]])
def test_sliding_scores_equal_window_features(shape):
    rng = np.random.default_rng(3)
    xyz = rng.uniform(0, [2.0, 2.0, 2.0], (30000, 3))
    vol = _volume(xyz, rng.uniform(0, 1, (30000, 3)), yaw=0.4)
    lay = FeatureLayout(k=4, disabled=("color",))
    w = rng.normal(size=lay.size)
    ws = score_windows(vol, np.array(shape), w, 0.25, lay, stride=0.25, min_points=1)
    flat = np.arange(ws.scores.size)
    pick = rng.choice(flat, min(100, len(flat)), replace=False)
    lo, hi = ws.boxes(pick)
    ref = window_features(vol.iv, vol.grid, lo, hi, lay) @ w + 0.25
    got = ws.scores.ravel()[pick]
    empty = ws.counts.ravel()[pick] < 1
    assert np.all(np.isneginf(got[empty]))  # windows without points are not scored
    assert np.allclose(got[~empty], ref[~empty], atol=1e-9)
