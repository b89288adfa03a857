"""A wall on every side of a space that holds one (``side-classes``, engine/detection/sides.py)."""
from __future__ import annotations

import numpy as np

from engine.detection.settings import DetectionSettings
from engine.detection.sides import SIDES, best_at_sides, settle_sides, side_of, side_windows
from engine.detection.sliding import WindowScores
from tiles.classes import CLASS_CODES

GRID = np.array([60, 40, 30])


def test_a_thin_box_near_an_end_lies_at_that_side():
    lo = np.array([[0, 5, 0], [59, 5, 0], [5, 1, 0], [5, 38, 0], [30, 5, 0], [0, 5, 0], [0, 0, 0]])
    hi = np.array([[1, 35, 30], [60, 35, 30], [50, 2, 30], [50, 40, 30], [31, 35, 30], [10, 35, 30], [1, 1, 30]])
    # x low, x high, y low, y high, a thin box mid-room, a thick one, a post thin both ways (not longer along a side)
    assert side_of(lo, hi, GRID, thin=2, reach=3).tolist() == [0, 1, 2, 3, -1, -1, -1]
    assert side_of(lo[:1] + [4, 0, 0], hi[:1] + [4, 0, 0], GRID, 2, 3).tolist() == [-1]  # beyond the reach
    assert [SIDES[s] for s in (0, 1, 2, 3)] == [(0, 0), (0, 1), (1, 0), (1, 1)]


def test_the_best_window_at_each_side_above_the_floor():
    px, py, pz = np.arange(0, 60), np.arange(0, 5), np.arange(0, 1)  # a wall window 1 x 35 x 30 sliding along x
    scores = np.full((len(px), len(py), len(pz)), -9.0)
    scores[1, 2, 0], scores[0, 4, 0] = -2.0, -2.5  # the low end: the best of the two
    scores[58, 1, 0] = -3.5  # the high end: under the floor
    scores[30, 0, 0] = 4.0  # mid-room: no side
    ws = WindowScores(np.array([1, 35, 30]), px, py, pz, scores, np.ones_like(scores))
    lo, hi, sc, atom = side_windows(ws, 7, GRID, thin=2, reach=np.array([3, 3, 3]), floor=-3.0)
    assert lo.tolist() == [[1, 2, 0]] and hi.tolist() == [[2, 37, 30]] and sc.tolist() == [-2.0]
    assert atom.tolist() == [7]
    lo, _, sc, _ = side_windows(ws, 7, GRID, 2, np.array([3, 3, 3]), floor=-4.0)
    assert lo.tolist() == [[1, 2, 0], [58, 1, 0]] and sc.tolist() == [-2.0, -3.5]
    # a window thick across every side (a table) has no side
    ws_thick = WindowScores(np.array([10, 8, 7]), px, py, pz, scores, np.ones_like(scores))
    assert side_windows(ws_thick, 7, GRID, 2, np.array([3, 3, 3]), floor=-9.5) is None


def test_the_best_box_at_each_side():
    lo = np.array([[1, 2, 0], [59, 3, 0], [58, 6, 0], [5, 0, 0], [30, 2, 0]])
    hi = np.array([[2, 37, 30], [60, 38, 30], [59, 36, 30], [50, 1, 30], [31, 37, 30]])
    score = np.array([5.0, -2.0, -1.0, -2.5, 9.0])
    assert best_at_sides(lo, hi, score, GRID, 2, np.array([3, 3, 3])).tolist() == [0, 2, 3]


def test_a_side_gets_a_sure_wall_only_where_no_wall_is_believed():
    lo = np.array([[0, 5, 0], [1, 2, 0], [59, 3, 0], [58, 6, 0], [5, 0, 0], [5, 38, 0], [10, 10, 0]])
    hi = np.array([[1, 35, 30], [2, 37, 30], [60, 38, 30], [59, 36, 30], [50, 1, 30], [50, 40, 30], [20, 20, 10]])
    score = np.array([1.5, -0.5, -2.0, -1.0, -4.0, -0.3, -1.0])
    of_class = np.array([True, True, True, True, True, True, False])  # the last is a table
    candidate = np.array([False, True, True, False, True, False, False])
    keep, sure = settle_sides(lo, hi, score, of_class, candidate, GRID, 2, np.array([3, 3, 3]))
    # x low: a wall scored 1.5 is believed, its candidate goes; x high: the wall re-ranked to -1.0 beats the
    # candidate's -2.0 and becomes sure, the candidate goes; y low: the candidate alone, sure; y high: a wall at
    # -0.3, sure; the table is no wall
    assert keep.tolist() == [True, False, False, True, True, True, True]
    assert sure.tolist() == [False, False, False, True, True, True, False]


def test_every_side_of_a_space_gets_a_sure_wall(buildings, trained):
    """Scores no window reaches: the space still gets its ceiling, its floor and one wall on each side of its box
    that holds one (``side-floor`` below every score), each marked sure; without ``side-classes`` none."""
    from engine.detection.proposals import SURE
    from engine.detection.space import detect_space
    from engine.spaces.points import index_spaces, load_space

    _, stores = buildings
    store = stores["test"]
    ref = max(index_spaces(store, "gt_space"), key=lambda r: r.count)
    pts = load_space(store, ref, "gt_space")
    strict = DetectionSettings.from_config(score_threshold=50.0, side_floor=-1e9, side_classes="wall")
    props = detect_space(pts, trained, strict)
    walls = [p for p in props if p.class_code == CLASS_CODES["wall"]]
    assert len(walls) == 4 and all(p.extra.get(SURE) for p in walls)
    assert all(p.score < 50.0 for p in walls)
    # the four walls are thin and face four different ways: two along each horizontal axis of the space
    thin = [int(np.argmin(p.world_size[:2])) for p in walls]
    assert sorted(thin) == [0, 0, 1, 1] and all(min(p.world_size[:2]) < 0.2 for p in walls)
    others = [p for p in props if p.class_code != CLASS_CODES["wall"]]
    assert sorted(p.class_code for p in others) == [CLASS_CODES["ceiling"], CLASS_CODES["floor"]]
    assert not any(p.extra.get(SURE) for p in others)
    off = detect_space(pts, trained, DetectionSettings.from_config(score_threshold=50.0, side_classes=""))
    assert sorted(p.class_code for p in off) == [CLASS_CODES["ceiling"], CLASS_CODES["floor"]]
    # a floor above every window's score: no side wall
    none = detect_space(pts, trained, DetectionSettings.from_config(score_threshold=50.0, side_floor=50.0))
    assert not [p for p in none if p.class_code == CLASS_CODES["wall"]]
