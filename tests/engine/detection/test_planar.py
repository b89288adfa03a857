"""A board's box along the wall's normal fitted to its points: bare or with a tray, never a chair in front."""
from __future__ import annotations

import numpy as np
import pytest

from engine.detection.planar import GAP, MIN_POINTS, element_run, fit_depth, fit_planar, wall_plane
from engine.detection.settings import DetectionSettings
from tiles.classes import ELEMENT_CLASSES

NOISE = 0.002
WALL = 3.0  # the wall's face at x = 3.0, the room at x < 3.0


def _scene(rng, tray: bool, chair: bool, chair_at: float = 0.4, side: bool = False) -> np.ndarray:
    """A wall face (x = WALL, y 0-6, z 0-3), a 2 cm board on it (y 2-4, z 1-2), maybe a tray, maybe a chair's
    back ``chair_at`` metres out, maybe a shelf's side across the board's front (from the wall to 40 cm out)."""
    n = 40000
    y, z = rng.uniform(0, 6, n), rng.uniform(0, 3, n)
    on_board = (y > 2) & (y < 4) & (z > 1) & (z < 2)
    x = np.where(on_board, WALL - 0.02, WALL)  # the board hides the wall behind it
    parts = [np.column_stack([x, y, z])]
    edge = rng.uniform(0, 0.02, 400)  # its edges, seen at an angle
    parts.append(np.column_stack([WALL - edge, np.where(rng.uniform(size=400) < 0.5, 2.0, 4.0), rng.uniform(1, 2, 400)]))
    if tray:  # 6 cm deep, 60 % of the width, at the bottom
        m = 300
        parts.append(np.column_stack([WALL - rng.uniform(0.0, 0.06, m), rng.uniform(2.4, 3.6, m), np.full(m, 1.0)]))
    if chair:  # a chair's back 40 cm in front
        m = 3000
        parts.append(np.column_stack([WALL - chair_at - rng.uniform(0, 0.05, m), rng.uniform(2.8, 3.3, m),
                                      rng.uniform(0.5, 1.1, m)]))
    if side:
        m = 3000
        parts.append(np.column_stack([WALL - rng.uniform(0, 0.4, m), np.full(m, 3.0), rng.uniform(0.8, 1.5, m)]))
    pts = np.concatenate(parts)
    return pts + rng.normal(0, NOISE, pts.shape) * np.array([1, 0, 0])


def _fit(pts, lo, hi, classes=("board",)):
    lo_m, hi_m = np.array([lo], float), np.array([hi], float)
    n = fit_planar(lo_m, hi_m, np.array([ELEMENT_CLASSES.index("board")]),
                   lambda a, b: pts[np.all((pts >= a) & (pts <= b), axis=1)], classes, 0.15, 0.3, 0.005)
    return n, lo_m[0], hi_m[0]


@pytest.mark.parametrize("tray, chair_at", [(False, None), (True, None), (False, 0.4), (False, 0.06)])
def test_the_box_runs_from_the_wall_to_the_front_of_the_board_and_its_tray(tray, chair_at):
    pts = _scene(np.random.default_rng(4), tray, chair_at is not None, chair_at or 0.4)
    # a detection on the voxel grid: 10 cm deep, straddling the wall, a little wider than the board
    n, lo, hi = _fit(pts, [2.9, 1.95, 0.95], [3.0, 4.05, 2.05])
    assert n == 1
    front = 0.06 if tray else 0.02
    assert hi[0] == pytest.approx(WALL, abs=3 * NOISE)
    # the tightest box of the element's points: its front is the farthest point of its face or tray (noise
    # included); a chair 40 cm out, or 6 cm out across a 4 cm gap, is not the board's
    assert WALL - front - 5 * NOISE <= lo[0] <= WALL - front
    assert (lo[1], hi[1], lo[2], hi[2]) == (1.95, 4.05, 0.95, 2.05)  # the other sides stay


def test_no_fit_without_wall_beside_or_for_other_classes():
    pts = _scene(np.random.default_rng(5), False, False)
    wide = _fit(pts, [2.9, -0.5, 0.95], [3.0, 6.5, 2.05])  # the box spans the whole wall: no wall beside it
    assert wide[0] == 0 and wide[1][0] == 2.9 and wide[2][0] == 3.0
    assert _fit(pts, [2.9, 1.95, 0.95], [3.0, 4.05, 2.05], classes=("window",))[0] == 0


def test_the_room_side_comes_from_the_space_when_the_strips_beside_hold_the_board():
    """A detection narrower than its board: the strips beside it lie on the board's face, which becomes the
    densest plane; the frame's bottom edge behind the face outnumbers the tray's points in front, so the points
    would put the room behind the board.  The space's extent says where the room is (the wall at its nearer end)."""
    rng = np.random.default_rng(9)
    n = 30000
    y, z = rng.uniform(1.8, 4.2, n), rng.uniform(0.9, 2.1, n)
    on_board = (y > 2) & (y < 4) & (z > 1) & (z < 2)
    face = np.column_stack([np.where(on_board, WALL - 0.02, WALL), y, z])
    m = 1200  # the frame's bottom edge, between the face and the wall
    edge = np.column_stack([WALL - rng.uniform(0, 0.02, m), rng.uniform(2.0, 4.0, m), np.full(m, 1.0)])
    k = 300  # the tray, 6 cm deep, in front
    tray = np.column_stack([WALL - rng.uniform(0.02, 0.06, k), rng.uniform(2.4, 3.6, k), np.full(k, 1.0)])
    pts = np.concatenate([face, edge, tray])
    pts[:, 0] += rng.normal(0, NOISE, len(pts))
    box = ([2.9, 2.3, 0.95], [3.0, 3.7, 2.05])  # 1.4 m of a 2 m board: the 0.3 m strips beside are on its face
    points_in = lambda a, b: pts[np.all((pts >= a) & (pts <= b), axis=1)]  # noqa: E731
    lo_m, hi_m = np.array([box[0]], float), np.array([box[1]], float)
    board = np.array([ELEMENT_CLASSES.index("board")])
    assert fit_planar(lo_m, hi_m, board, points_in, ("board",), 0.15, 0.3, 0.005, np.array([3.0, 6.0, 3.0])) == 1
    assert WALL - 0.06 - 5 * NOISE <= lo_m[0, 0] <= WALL - 0.06 and hi_m[0, 0] == pytest.approx(WALL, abs=4 * NOISE)
    guess_lo, guess_hi = np.array([box[0]], float), np.array([box[1]], float)
    fit_planar(guess_lo, guess_hi, board, points_in, ("board",), 0.15, 0.3, 0.005)  # the side from the counts
    assert guess_lo[0, 0] > WALL - 0.05  # the tray left out: the fit went the wrong way


def test_no_fit_where_a_surface_runs_on_across_the_front():
    """A shelf's side from the wall to 40 cm out within the footprint: the points do not show the board's front."""
    pts = _scene(np.random.default_rng(7), False, False, side=True)
    n, lo, hi = _fit(pts, [2.9, 1.95, 0.95], [3.0, 4.05, 2.05])
    assert n == 0 and lo[0] == 2.9 and hi[0] == 3.0


def test_the_element_is_the_first_run_of_points_from_the_back():
    rng = np.random.default_rng(8)
    face = rng.uniform(0.0, 0.03, 200)
    stray = np.array([-0.025])  # fewer than MIN_POINTS behind: not a run of its own
    chair = rng.uniform(0.03 + 1.5 * GAP, 0.1, 300)
    run = element_run(np.concatenate([chair, face, stray]))
    assert run is not None and run[0] == pytest.approx(face.min()) and run[-1] == pytest.approx(face.max())
    assert element_run(np.linspace(0, 1, MIN_POINTS - 1)) is None


def test_the_wall_plane_is_the_densest_plane():
    rng = np.random.default_rng(6)
    v = np.concatenate([rng.normal(1.234, NOISE, 5000), rng.uniform(1.0, 1.5, 500)])
    assert wall_plane(v) == pytest.approx(1.234, abs=NOISE)
    assert wall_plane(v[:5]) is None and fit_depth(v, v[:5], 0.15, 0.005) is None


def test_the_setting_is_boards_by_default_and_checked():
    assert DetectionSettings.from_config().planar_classes == ("board",)
    with pytest.raises(ValueError, match="planar-depth"):
        DetectionSettings(planar_depth=0)
