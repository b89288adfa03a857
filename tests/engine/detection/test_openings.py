"""A window's width and height fitted to its opening in the wall's face (engine/detection/openings.py)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from engine.detection.openings import cell_size, fit_openings, one_per_opening, open_cells
from engine.detection.planar import CELL, MAX_CELL
from engine.detection.settings import DetectionSettings
from tiles.classes import ELEMENT_CLASSES

WINDOW = ELEMENT_CLASSES.index("window")
EXTENT = np.array([8.0, 5.0, 3.0])


def _wall_with_window(rng, u0, u1, z0, z1, n=60000):
    """The wall of an 8 x 3 m room, its room-side face at y = 0.35 (the space's frame holds the wall's reveal),
    scanned from the room, with a window opening u0-u1, z0-z1 whose glass is 0.15 m deep in the reveal."""
    face = rng.uniform([0.0, 0.347, 0.0], [8.0, 0.353, 3.0], (n, 3))
    hole = (face[:, 0] > u0) & (face[:, 0] < u1) & (face[:, 2] > z0) & (face[:, 2] < z1)
    glass = rng.uniform([u0, 0.198, z0], [u1, 0.202, z1], (int(hole.sum() // 2), 3))
    floor = rng.uniform([0.0, 0.0, 0.0], [8.0, 5.0, 0.003], (n, 3))
    return np.concatenate([face[~hole], glass, floor])


def _query(points):
    return lambda lo, hi: points[np.all((points >= np.asarray(lo) - 0.1) & (points <= np.asarray(hi) + 0.1), axis=1)]


def test_a_window_box_takes_the_size_of_its_opening():
    rng = np.random.default_rng(0)
    pts = _wall_with_window(rng, 2.0, 5.2, 0.9, 2.1)  # a 3.2 m ribbon window
    # the detector's box: a training window's size, 1.5 x 1.4 m, at its place
    lo, hi = np.array([[2.8, 0.05, 0.8]]), np.array([[4.3, 0.37, 2.2]])
    fit_openings(lo, hi, np.array([WINDOW]), _query(pts), ("window",), 1.5, EXTENT)
    assert np.allclose([lo[0, 0], hi[0, 0], lo[0, 2], hi[0, 2]], [2.0, 5.2, 0.9, 2.1], atol=0.06)
    assert lo[0, 1] == 0.05 and hi[0, 1] == 0.37  # the depth is left as it is


def test_no_opening_under_the_box_or_one_that_runs_on_leaves_it():
    rng = np.random.default_rng(1)
    solid = _wall_with_window(rng, 0.0, 0.0, 0.0, 0.0)  # no window
    lo, hi = np.array([[2.8, 0.05, 0.8]]), np.array([[4.3, 0.37, 2.2]])
    fit_openings(lo, hi, np.array([WINDOW]), _query(solid), ("window",), 1.5, EXTENT)
    assert np.allclose(lo, [[2.8, 0.05, 0.8]]) and np.allclose(hi, [[4.3, 0.37, 2.2]])
    wide = _wall_with_window(rng, 0.5, 7.5, 0.9, 2.1)
    # other classes are left alone
    lo, hi = np.array([[2.8, 0.05, 0.8]]), np.array([[4.3, 0.37, 2.2]])
    fit_openings(lo, hi, np.array([ELEMENT_CLASSES.index("door")]), _query(wide), ("window",), 1.5, EXTENT)
    assert np.allclose(hi, [[4.3, 0.37, 2.2]])


def test_a_face_hidden_by_furniture_is_no_opening():
    rng = np.random.default_rng(2)
    pts = _wall_with_window(rng, 2.0, 5.2, 0.9, 2.1)
    # a desk under the window hides the face from 0.3 to 0.75 m: no point there, its top in front of the wall
    hidden = (pts[:, 1] > 0.3) & (pts[:, 0] > 1.5) & (pts[:, 0] < 5.7) & (pts[:, 2] > 0.3) & (pts[:, 2] < 0.75)
    desk = rng.uniform([1.5, 0.5, 0.74], [5.7, 1.1, 0.76], (5000, 3))
    pts = np.concatenate([pts[~hidden], desk])
    lo, hi = np.array([[2.8, 0.05, 0.6]]), np.array([[4.3, 0.37, 2.2]])
    fit_openings(lo, hi, np.array([WINDOW]), _query(pts), ("window",), 1.5, EXTENT)
    assert np.allclose([lo[0, 0], hi[0, 0], lo[0, 2], hi[0, 2]], [2.0, 5.2, 0.9, 2.1], atol=0.06)


def test_opening_settings():
    assert DetectionSettings.from_config().opening_classes == ("window",)
    assert DetectionSettings.from_config(opening_classes="").opening_classes == ()
    with pytest.raises(ValueError, match="opening-grow"):
        DetectionSettings(opening_grow=-1.0)
    assert DetectionSettings.from_config().opening_bonus == 2.0
    for bad in (-1.0, float("nan")):
        with pytest.raises(ValueError, match="opening-bonus"):
            DetectionSettings(opening_bonus=bad)


def test_a_ribbon_longer_than_the_search_is_followed_along_the_wall():
    """An opening wider than the search (7 m, searched 1 m beyond a 1.5 m box) is followed column by column to its
    ends; a wall that drifts off the face's plane beyond a window (open above and below it too: a bowed wall, a
    frame a little off) is not a window, and the run stops where the wall stops being one."""
    rng = np.random.default_rng(3)
    wide = _wall_with_window(rng, 0.5, 7.5, 0.9, 2.1)
    lo, hi = np.array([[3.0, 0.05, 0.8]]), np.array([[4.5, 0.37, 2.2]])
    fit_openings(lo, hi, np.array([WINDOW]), _query(wide), ("window",), 1.0, EXTENT)
    assert np.allclose([lo[0, 0], hi[0, 0], lo[0, 2], hi[0, 2]], [0.5, 7.5, 0.9, 2.1], atol=0.06)
    # from x = 5.5 on, the whole wall lies 6 cm deeper than its face (it drifts away): the ribbon ends at 6.0
    drift = _wall_with_window(rng, 1.0, 6.0, 0.9, 2.1)
    far = (drift[:, 0] > 5.5) & (drift[:, 1] > 0.3)
    drift[far, 1] -= 0.06
    lo, hi = np.array([[2.0, 0.05, 0.8]]), np.array([[3.5, 0.37, 2.2]])
    fit_openings(lo, hi, np.array([WINDOW]), _query(drift), ("window",), 1.0, EXTENT)
    assert np.allclose([lo[0, 0], lo[0, 2], hi[0, 2]], [1.0, 0.9, 2.1], atol=0.06)
    assert 5.4 <= hi[0, 0] <= 6.05


def test_the_pieces_of_one_opening_keep_the_best():
    """Followed detections (a ribbon's pieces, each fitted to the whole ribbon) whose boxes overlap keep the
    best-scored, as the union of their boxes along the wall and in height (its own depth); boxes apart, and
    detections not followed, stay as they are."""
    lo = np.array([[0.5, 0.0, 0.9], [0.5, 0.0, 1.0], [0.52, 0.0, 0.85], [0.5, 0.0, 0.9], [5.0, 0.0, 0.9]])
    hi = np.array([[7.5, 0.3, 2.1], [7.4, 0.3, 2.1], [7.5, 0.32, 2.1], [7.5, 0.3, 2.1], [6.0, 0.3, 2.1]])
    followed = np.array([True, True, True, False, True])
    keep = one_per_opening(lo, hi, np.array([1.0, 3.0, 2.0, 5.0, 0.5]), followed, 0.3)
    assert keep.tolist() == [False, True, False, True, True]
    assert np.allclose(lo[1], [0.5, 0.0, 0.85]) and np.allclose(hi[1], [7.5, 0.3, 2.1])  # the union, its depth
    assert np.allclose(hi[4], [6.0, 0.3, 2.1]) and np.allclose(lo[3], [0.5, 0.0, 0.9])


def test_fit_openings_says_which_openings_it_followed():
    rng = np.random.default_rng(4)
    pts = _wall_with_window(rng, 0.5, 7.5, 0.9, 2.1)
    lo, hi = np.array([[3.0, 0.05, 0.8], [0.6, 0.05, 0.9]]), np.array([[4.5, 0.37, 2.2], [7.4, 0.37, 2.1]])
    followed, sill = fit_openings(lo, hi, np.array([WINDOW, WINDOW]), _query(pts), ("window",), 1.0, EXTENT)
    assert followed.tolist() == [True, False]  # the second box's search holds the whole opening
    assert sill.tolist() == [True, True]


def test_an_opening_counts_as_a_window_s_only_with_a_sill():
    """An opening whose bottom is above the floor (a sill) is a window's evidence; a doorway reaching the floor,
    a solid wall and another class's detection are not."""
    rng = np.random.default_rng(9)
    window = _wall_with_window(rng, 2.0, 3.5, 0.9, 2.1)
    doorway = _wall_with_window(rng, 2.0, 3.0, 0.0, 2.1)
    solid = _wall_with_window(rng, 0.0, 0.0, 0.0, 0.0)
    for pts, classes, want in ((window, ("window",), True), (doorway, ("window",), False),
                               (solid, ("window",), False), (window, ("board",), False)):
        lo, hi = np.array([[1.9, 0.05, 0.5]]), np.array([[3.6, 0.37, 2.3]])
        _, sill = fit_openings(lo, hi, np.array([WINDOW]), _query(pts), classes, 1.0, EXTENT)
        assert sill.tolist() == [want]


def _fitted(points, lo, hi, grow):
    """The window box ``lo``-``hi`` fitted to its opening in ``points``: its ``u0, u1, z0, z1``."""
    lo, hi = np.array([lo], dtype=float), np.array([hi], dtype=float)
    fit_openings(lo, hi, np.array([WINDOW]), _query(points), ("window",), grow, EXTENT)
    return [lo[0, 0], hi[0, 0], lo[0, 2], hi[0, 2]]


def test_a_narrow_window_in_a_wide_box_takes_its_opening_but_a_piece_of_a_wider_one_does_not():
    """A 0.6 m window between piers covers under MIN_SHARE of a training window's 2.2 m box: it is still the box's
    opening.  A piece of a wider opening, cut off by a seam of stray points on the face's plane, is not (the piece
    has the rest of the opening beside it, not a pier), and leaves the box as it is."""
    rng = np.random.default_rng(5)
    box = ([2.2, 0.05, 0.8], [4.4, 0.37, 2.2])
    narrow = _wall_with_window(rng, 3.0, 3.6, 0.9, 2.1)
    assert np.allclose(_fitted(narrow, *box, 1.0), [3.0, 3.6, 0.9, 2.1], atol=0.06)
    # a 4 m opening with stray face points in a 3 cm seam at u = 3.6: the piece 3.0-3.6 has no pier on its right
    wide = _wall_with_window(rng, 3.0, 7.0, 0.9, 2.1)
    cut = np.concatenate([wide, rng.uniform([3.585, 0.347, 0.9], [3.615, 0.353, 2.1], (400, 3))])
    assert np.allclose(_fitted(cut, [1.4, 0.05, 0.8], [3.65, 0.37, 2.2], 0.5)[:2], [1.4, 3.65])
    # a narrow window cut across by a seam at z = 1.5 (a transom's stray points): neither half has a lintel or a
    # sill of wall on the seam's side, so neither is taken for the window
    cut = np.concatenate([narrow, rng.uniform([3.0, 0.347, 1.485], [3.6, 0.353, 1.515], (400, 3))])
    assert np.allclose(_fitted(cut, *box, 1.0), [2.2, 4.4, 0.8, 2.2])


def test_a_sparse_scan_finds_its_opening_on_cells_sized_to_its_face():
    """At 300 points per m² of face a 5 cm cell holds 0.75 of them on average, and the glass, at half that, leaves
    most of the opening's cells empty: on 5 cm cells the face is full of holes and the opening is specks, and the
    box stays a training window's.  Cells sized to the face's density (four points a cell) find the opening; a
    face hidden by a desk is still no opening."""
    rng = np.random.default_rng(6)
    pts = _wall_with_window(rng, 2.0, 3.7, 0.9, 2.2, n=7200)
    box = ([1.6, 0.05, 0.7], [4.3, 0.37, 2.5])
    assert np.allclose(_fitted(pts, *box, 1.5), [2.0, 3.7, 0.9, 2.2], atol=0.15)
    hidden = (pts[:, 1] > 0.3) & (pts[:, 0] > 1.5) & (pts[:, 0] < 4.2) & (pts[:, 2] > 0.3) & (pts[:, 2] < 0.75)
    desk = rng.uniform([1.5, 0.5, 0.74], [4.2, 1.1, 0.76], (800, 3))
    assert np.allclose(_fitted(np.concatenate([pts[~hidden], desk]), *box, 1.5), [2.0, 3.7, 0.9, 2.2], atol=0.15)


def test_the_cell_follows_the_face_density_beside_the_box():
    rng = np.random.default_rng(7)
    u, z = rng.uniform(0.0, 4.0, 4000), rng.uniform(0.0, 2.5, 4000)  # 400 points per m² over the search
    on = np.ones(4000, dtype=bool)
    on[(u > 1.0) & (u < 3.0) & (z > 0.5) & (z < 2.0)] = False  # the box holds an opening: no face there
    assert cell_size(on, u, z, (0.0, 4.0), (0.0, 2.5), (1.0, 3.0), (0.5, 2.0)) == pytest.approx(0.1, rel=0.05)
    assert cell_size(on[:40], u[:40], z[:40], (0.0, 4.0), (0.0, 2.5), (1.0, 3.0), (0.5, 2.0)) == MAX_CELL
    dense = np.ones(200000, dtype=bool)
    assert cell_size(dense, *rng.uniform(0.0, 2.5, (2, 200000)), (0.0, 2.5), (0.0, 2.5), (3.0, 3.0), (3.0, 3.0)) == CELL


def test_open_cells_join_the_specks_of_a_sparse_opening_but_not_a_hidden_face():
    wall = np.ones((20, 16), dtype=bool)
    wall[4:16, 3:13] = False  # the opening and, below it, a face hidden by a desk (no point at all)
    seen = np.zeros_like(wall)
    seen[4:16:2, 7:13:2] = True  # glass: one cell in four holds a point deeper than the face
    seen[5:16:2, 8:13:2] = True
    assert ndimage.label(seen & ~wall)[1] > 1  # specks
    found = open_cells(wall, seen)
    labels, count = ndimage.label(found)
    assert count == 1 and found[4:16, 7:13].sum() >= 0.9 * 72
    assert not found[:, :6].any() and not found[wall].any()  # the hidden face stays closed; wall is never open
