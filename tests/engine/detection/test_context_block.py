"""The context block of a window's features: the slabs beside its faces, on a wall with a board and by hand."""
from __future__ import annotations

import numpy as np

from engine.detection.canonical import CanonicalFrame
from engine.detection.features import window_features
from engine.detection.layout import FeatureLayout
from engine.detection.volume import SpaceVolume


def _volume(xyz, rgb=None, extent=(2.0, 2.0, 2.0), voxel=0.1, yaw=0.0):
    frame = CanonicalFrame(yaw, [0.0, 0.0, 0.0], extent)
    return SpaceVolume.build(frame.from_metric(xyz), rgb, frame, voxel, 10**7)


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


def test_context_bounds_hold_for_every_window():
    """Each context feature of any window lies within :func:`context_bounds` of its space, and a space of one
    colour has no contrast to bound."""
    from engine.detection.context_block import context_bounds, window_context

    rng = np.random.default_rng(3)
    vol, _ = _wall_with_board(rng, board_rgb=(0.1, 0.9, 0.2))
    lo_b, hi_b = vol.context_range
    n = np.asarray(vol.grid.shape)
    lo = rng.integers(0, n, (4000, 3))
    hi = np.minimum(lo + rng.integers(1, 12, (4000, 3)), n)
    ctx = window_context(vol.iv, vol.grid, lo, hi)
    assert np.all(ctx >= lo_b - 1e-12) and np.all(ctx <= hi_b + 1e-12)
    assert np.all(lo_b[6:9] < -0.1) and ctx[:, 6:9].min() < -0.05 and ctx[:, 6:9].max() > 0.05  # room to bound
    grey, _ = _wall_with_board(rng, board_rgb=(0.8, 0.78, 0.74))  # the wall's colour
    g_lo, g_hi = context_bounds(grey.context_iv)
    assert np.all(np.abs(g_lo[6:]) < 1e-6) and np.all(np.abs(g_hi[6:]) < 1e-6)
    assert np.array_equal(g_hi[:6], np.ones(6)) and np.array_equal(g_lo[:6], np.zeros(6))
