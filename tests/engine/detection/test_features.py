"""Table 1 features from summed voxel moments: hand-made patterns give what they should."""
from __future__ import annotations

import numpy as np
import pytest

from engine.detection import moments as mom
from engine.detection.canonical import CanonicalFrame
from engine.detection.colours import COLOUR_TARGET, normalise_colours
from engine.detection.features import window_features
from engine.detection.global_block import global_features, global_scores, tent_code
from engine.detection.layout import FeatureLayout
from engine.detection.local_block import local_features
from engine.detection.sliding import axis_positions, non_maximum_suppression, score_windows
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


def test_curvature_of_a_corner_and_normals_from_moments_match_eigh():
    rng = np.random.default_rng(2)
    sums = np.zeros((50, 13))
    for i in range(50):
        p = rng.normal(size=(30, 3)) * rng.uniform(0.01, 1, 3)
        sums[i, 0] = 30
        sums[i, 1:4] = p.sum(0)
        for k, (a, b) in enumerate(((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))):
            sums[i, 4 + k] = (p[:, a] * p[:, b]).sum()
        w, v = np.linalg.eigh(np.cov(p.T, bias=True))
        f = local_features(sums[i:i + 1], np.array([30.0]), 1)[0]
        assert f[8] == pytest.approx(w[0] / w.sum(), rel=1e-6)
        assert np.allclose(f[5:8], np.abs(v[:, 0]), atol=1e-6)


def test_tent_code():
    c = tent_code(np.array([0.0, 0.1, 0.5, 1.2, -3]), (0, 0.25, 0.5, 0.75, 1))
    assert np.allclose(c.sum(1), 1)
    assert np.allclose(c[1], [0.6, 0.4, 0, 0, 0])
    assert np.allclose(c[2], [0, 0, 1, 0, 0]) and np.allclose(c[3], [0, 0, 0, 0, 1]) and np.allclose(c[4], [1, 0, 0, 0, 0])


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


def test_positions_reach_both_faces():
    p = axis_positions(23, 5, 0.25)
    assert p[0] == 0 and p[-1] == 18 and np.all(np.diff(p) >= 1)
    assert axis_positions(10, 10, 0.25).tolist() == [0]
    assert axis_positions(10, 12, 0.25).tolist() == [0]


def test_nms_keeps_best_of_overlapping_boxes():
    lo = np.array([[0, 0, 0], [1, 0, 0], [10, 0, 0], [0, 0, 0]])
    hi = lo + [10, 2, 2]
    hi[3] = [2, 2, 2]
    keep = non_maximum_suppression(lo, hi, np.array([0.5, 0.9, 0.7, 0.1]), 0.3, 10)
    assert keep.tolist() == [1, 2, 3]


def test_colour_normalisation_cancels_a_space_exposure_and_keeps_contrast():
    rng = np.random.default_rng(4)
    n = 6000
    # a light ceiling over a dark floor, the same space scanned at full and at half exposure
    xyz = np.c_[rng.uniform(0, 2, n), rng.uniform(0, 2, n), np.where(np.arange(n) < 4000, 1.95, 0.05)]
    rgb = np.where((np.arange(n) < 4000)[:, None], [0.9, 0.9, 0.85], [0.3, 0.2, 0.2])
    rgb = rgb + rng.normal(0, 0.01, (n, 3))
    lo, hi = np.array([[0, 0, 0]]), np.array([[20, 20, 20]])
    lay = FeatureLayout(k=2)
    assert lay.colour == "space-median"

    def colour_block(scale, mode):
        frame = CanonicalFrame(0.0, [0.0, 0.0, 0.0], (2.0, 2.0, 2.0))
        vol = SpaceVolume.build(xyz, rgb * scale, frame, 0.1, 10**7, mode)
        return _local(lay, window_features(vol.iv, vol.grid, lo, hi, lay)[0])[..., 2:5]

    full, half = colour_block(1.0, "space-median"), colour_block(0.5, "space-median")
    assert np.allclose(full, half)  # the exposure cancels
    # the median luminance (the ceiling's, 4000 of 6000 points) becomes the target; the floor stays darker
    assert full[:, :, 1].mean() == pytest.approx(COLOUR_TARGET, rel=0.02)
    assert full[:, :, 0].mean() < 0.5 * full[:, :, 1].mean()
    raw_full, raw_half = colour_block(1.0, "none"), colour_block(0.5, "none")
    assert np.allclose(raw_half, 0.5 * raw_full) and not np.allclose(raw_full, raw_half, atol=0.1)
    assert normalise_colours(None) is None
    with pytest.raises(ValueError, match="colour"):
        FeatureLayout(k=2, colour="gamma")


def test_layout_colour_mode_round_trips_and_old_models_read_as_raw():
    lay = FeatureLayout(k=2)
    assert FeatureLayout.from_json(lay.to_json()).colour == "space-median"
    old = {k: v for k, v in lay.to_json().items() if k != "colour"}  # written before the mode existed
    assert FeatureLayout.from_json(old).colour == "none"


@pytest.mark.parametrize("shape", [(7, 5, 9), (12, 24, 8), (1, 1, 1)])
def test_global_scores_are_the_global_block_times_the_weights(shape):
    rng = np.random.default_rng(sum(shape))
    grid = mom.VoxelGrid.covering([3.0, 2.4, 2.2], 0.1, 10**6)
    n = np.asarray(grid.shape)
    shape = np.minimum(shape, n)
    pos = [np.unique(np.append(np.arange(0, n[a] - shape[a] + 1, 2), n[a] - shape[a])) for a in range(3)]
    lo = np.stack(np.meshgrid(*pos, indexing="ij"), axis=-1).reshape(-1, 3)
    size = np.broadcast_to(shape, lo.shape)
    i, j, k = np.unravel_index(np.arange(len(lo)), [len(p) for p in pos])
    for boundary in (True, False):  # the current layout, and one written before the boundary code
        lay = FeatureLayout(k=2, boundary=boundary)
        w = rng.normal(size=(3, lay.n_global))
        terms, const = global_scores(pos, shape, grid.shape, grid.voxel, w, boundary)
        want = global_features(lo / n, size / n, size * grid.voxel, n * grid.voxel if boundary else None) @ w.T
        got = terms[0][:, i] + terms[1][:, j] + terms[2][:, k] + const[:, None]
        assert np.allclose(got.T, want, rtol=0, atol=1e-12)
        assert np.ptp(want[:, 0]) > 0.1  # the positions matter


def test_boundary_code_is_the_metric_distance_to_the_nearer_end():
    """A window against an end of a long space is at distance 0 along that axis whatever the room's size."""
    from engine.detection.global_block import BOUNDARY_TENTS, boundary_distance

    ext = np.array([20.0, 4.0, 3.0])
    pos = np.array([0.0, 0.25, 0.5])
    size = np.array([0.1, 0.5, 0.5])
    np.testing.assert_allclose(boundary_distance(pos, size, ext), [0.0, 1.0, 0.0])
    g = global_features(pos, size, size * ext, ext)
    code = g[-3 * len(BOUNDARY_TENTS):].reshape(3, -1)
    np.testing.assert_allclose(code, [[1, 0, 0, 0, 0], [0, 0, 0, 1, 0], [1, 0, 0, 0, 0]])
    old = FeatureLayout.from_json({k: v for k, v in FeatureLayout().to_json().items() if k not in ("boundary", "size")})
    assert not old.boundary and old.size == FeatureLayout().size - 15 and "boundary_code" not in old.spans
    assert FeatureLayout.from_json(FeatureLayout().to_json()).boundary


def _wall_with_board(rng, board_rgb=(0.95, 0.95, 0.93), wall_rgb=(0.8, 0.78, 0.74)):
    """A wall (plane y = 0.05) 4 m long and 3 m high with a pale board 2 cm proud of it (x 1.5-2.5, z 1-2)."""
    n = 60000
    xyz = np.c_[rng.uniform(0, 4, n), 0.05 + rng.normal(0, 0.002, n), rng.uniform(0, 3, n)]
    board = (xyz[:, 0] >= 1.5) & (xyz[:, 0] < 2.5) & (xyz[:, 2] >= 1.0) & (xyz[:, 2] < 2.0)
    xyz[board, 1] = 0.07
    rgb = np.where(board[:, None], board_rgb, wall_rgb)
    return _volume(xyz, rgb, extent=(4.0, 3.0, 3.0)), board


def test_context_block_sees_a_board_against_its_wall():
    """The board's window is brighter than the slabs beside it along the wall; a plain wall patch is not."""
    from engine.detection.context_block import CONTEXT_MARGIN, CONTEXT_SIZE, context_margin, window_context

    rng = np.random.default_rng(11)
    vol, _ = _wall_with_board(rng)
    lay = FeatureLayout(k=2)
    assert lay.size == lay.local_end + CONTEXT_SIZE and lay.spans["context_fill"] == [(lay.local_end, lay.local_end + 6)]
    assert list(context_margin(vol.grid.voxel)) == [round(CONTEXT_MARGIN / 0.1)] * 3
    lo = np.array([[15, 0, 10], [2, 0, 10]])  # the board's window, and a wall patch away from it
    hi = np.array([[25, 1, 20], [10, 1, 20]])
    ctx = window_context(vol.iv, vol.grid, lo, hi)
    assert np.array_equal(window_features(vol.iv, vol.grid, lo, hi, lay)[:, lay.local_end:], ctx)
    board, wall = ctx
    # the wall continues on both sides along x and z: a 0.3 m slab beside a 1 m window holds 0.3 / 1.3 of
    # the points; along y (the room, and behind the wall) nothing
    np.testing.assert_allclose(board[[0, 1, 4, 5]], 0.3 / 1.3, atol=0.02)
    assert board[2] == 0 and board[3] == 0
    # luminance contrast with the slabs along x and z: the board's 0.94 against the wall's 0.77 (times the
    # space's normalisation); none along y (no points there), the same sign in r, g, b
    assert board[6] > 0.05 and board[8] > 0.05 and board[7] == 0
    assert np.array_equal(board[9:12], np.abs(board[6:9])) and np.all(board[12:15] > 0.05)
    assert np.all(np.abs(wall[6:15]) < 1e-9)  # a plain wall patch: no contrast
    # a dark board: the contrast changes sign, its absolute value does not
    dark, _ = _wall_with_board(np.random.default_rng(11), board_rgb=(0.15, 0.25, 0.2))
    d = window_context(dark.iv, dark.grid, lo[:1], hi[:1])[0]
    assert d[6] < -0.05 and d[9] > 0.05


def test_context_features_from_hand_made_sums():
    from engine.detection.context_block import context_features

    window = np.array([10.0, 5.0, 5.0, 5.0])  # 10 points of luminance 0.5
    slabs = np.zeros((6, 4))
    slabs[0] = [30.0, 6.0, 6.0, 6.0]  # x-: 30 points of luminance 0.2
    slabs[5] = [10.0, 9.0, 9.0, 9.0]  # z+: 10 points of luminance 0.9
    f = context_features(window, slabs)
    np.testing.assert_allclose(f[:6], [0.0, 0.75, 0.0, 0.0, 0.0, 0.5])
    np.testing.assert_allclose(f[6:12], [0.3, 0.0, -0.4, 0.3, 0.0, 0.4])
    np.testing.assert_allclose(f[12:15], [0.5 - 15.0 / 40.0] * 3)
    assert np.all(context_features(np.zeros(4), slabs)[6:] == 0)  # an empty window has no contrast


def test_layouts_written_before_the_context_block_load_without_it():
    d = FeatureLayout().to_json()
    old = FeatureLayout.from_json({k: v for k, v in d.items() if k not in ("context", "size")})
    assert not old.context and old.size == FeatureLayout().size - 15 and "context_fill" not in old.spans
    assert old.local_end == old.size
    assert FeatureLayout.from_json(d).context
    assert not FeatureLayout(k=2).without(("context_color",)).mask[-9:].any()
