"""A free-standing element's horizontal sides fitted to its points, its base included (engine/detection/footprint.py)."""
from __future__ import annotations

import numpy as np
import pytest

from engine.detection.footprint import element_points, fit_footprints, floor_level
from engine.detection.settings import DetectionSettings
from tiles.classes import ELEMENT_CLASSES

CHAIR = ELEMENT_CLASSES.index("chair")
EXTENT = np.array([6.0, 5.0, 3.0])


def _slab(rng, lo, hi, n):
    return rng.uniform(lo, hi, (n, 3))


def _office_chair(rng, at=(2.0, 2.0), base=0.7, noise=0.005, post=200) -> np.ndarray:
    """An office chair at ``at``: a star base ``base`` wide (two crossed bars 0-7 cm high), a post (``post``
    points: 0 where the seat hides it from every scanner), a 0.46 m seat at 0.45 m and a back; the floor around
    it."""
    x, y = at
    b, s = base / 2, 0.23
    parts = [_slab(rng, [x - b, y - 0.025, 0.0], [x + b, y + 0.025, 0.07], 400),
             _slab(rng, [x - 0.025, y - b, 0.0], [x + 0.025, y + b, 0.07], 400),
             _slab(rng, [x - 0.025, y - 0.025, 0.07], [x + 0.025, y + 0.025, 0.42], post),
             _slab(rng, [x - s, y - s, 0.42], [x + s, y + s, 0.49], 1500),
             _slab(rng, [x - 0.22, y + 0.17, 0.49], [x + 0.22, y + 0.23, 0.95], 1000)]
    floor = _slab(rng, [0.0, 0.0, 0.0], [6.0, 5.0, 0.0], 60000)
    pts = np.concatenate(parts + [floor])
    return pts + rng.normal(0.0, noise, pts.shape)


def _query(points):
    return lambda lo, hi: points[np.all((points >= np.asarray(lo) - 0.1) & (points <= np.asarray(hi) + 0.1), axis=1)]


def test_floor_level_is_the_top_of_the_densest_low_bin():
    rng = np.random.default_rng(0)
    z = np.concatenate([rng.normal(0.0, 0.002, 5000), rng.uniform(0.0, 1.0, 500)])
    assert 0.0 <= floor_level(z, -0.01) <= 0.02
    assert floor_level(np.array([0.5, 0.6]), 0.0) is None  # no points near the bottom


def test_a_box_too_wide_takes_the_chairs_base_not_only_its_seat():
    rng = np.random.default_rng(1)
    pts = _office_chair(rng, base=0.7)
    lo, hi = np.array([[1.6, 1.6, 0.0]]), np.array([[2.4, 2.4, 1.0]])  # 0.8 m: a training chair's box
    fit_footprints(lo, hi, np.array([CHAIR]), _query(pts), ("chair",), 0.1, EXTENT)
    width = hi[0, :2] - lo[0, :2]
    assert np.all((width > 0.62) & (width < 0.72)), width  # the base's 0.7 m (less a few strays), not the seat's 0.46 m
    assert np.all(np.abs(0.5 * (lo[0, :2] + hi[0, :2]) - 2.0) < 0.02)
    assert lo[0, 2] == 0.0 and hi[0, 2] == 1.0  # the height stays


def test_a_base_apart_from_its_seat_is_the_chairs_and_a_bin_beside_it_is_not():
    """Without a point on the post the base and the seat are two parts: the base, wholly below the seat and centred
    under it, is still the chair's; a bin beside the chair, not touching it, is left out."""
    rng = np.random.default_rng(5)
    pts = np.concatenate([_office_chair(rng, base=0.7, post=0), _slab(rng, [2.45, 1.8, 0.0], [2.55, 2.2, 0.3], 800)])
    lo, hi = np.array([[1.6, 1.6, 0.0]]), np.array([[2.4, 2.4, 1.0]])
    fit_footprints(lo, hi, np.array([CHAIR]), _query(pts), ("chair",), 0.1, EXTENT)
    width = hi[0, :2] - lo[0, :2]
    assert np.all((width > 0.62) & (width < 0.72)), width  # the base's, not the seat's 0.46 m, and not the bin's
    assert np.all(np.abs(0.5 * (lo[0, :2] + hi[0, :2]) - 2.0) < 0.02)


def test_a_side_where_a_neighbour_runs_on_stays_and_other_classes_are_left_alone():
    rng = np.random.default_rng(2)
    # a table top from x = 2.2 on, over the chair's seat height, running past the grown box
    table = _slab(rng, [2.2, 1.0, 0.72], [4.0, 3.0, 0.75], 20000)
    pts = np.concatenate([_office_chair(rng, base=0.56), table])
    lo, hi = np.array([[1.6, 1.6, 0.0]]), np.array([[2.4, 2.4, 1.0]])
    fit_footprints(lo, hi, np.array([CHAIR]), _query(pts), ("chair",), 0.1, EXTENT)
    assert hi[0, 0] == 2.4 and hi[0, 1] == 2.4  # x runs on into the table (and so does y, under it)
    assert abs(lo[0, 0] - 1.72) < 0.03  # the free side comes in to the base
    lo2, hi2 = np.array([[1.6, 1.6, 0.0]]), np.array([[2.4, 2.4, 1.0]])
    fit_footprints(lo2, hi2, np.array([ELEMENT_CLASSES.index("table")]), _query(pts), ("chair",), 0.1, EXTENT)
    assert lo2[0, 0] == 1.6 and hi2[0, 0] == 2.4


def test_a_neighbour_that_does_not_touch_the_chair_is_left_out():
    rng = np.random.default_rng(3)
    # a bin 0.3 m wide standing 8 cm from the chair's base, inside the grown box but not to its edge
    bin_ = _slab(rng, [2.43, 1.85, 0.0], [2.47, 2.15, 0.5], 3000)
    chair = _office_chair(rng, base=0.56)
    pts = np.concatenate([chair, bin_])
    boxes = []
    for cloud in (chair, pts):  # the box reaches over the bin
        lo, hi = np.array([[1.6, 1.6, 0.0]]), np.array([[2.5, 2.4, 1.0]])
        fit_footprints(lo, hi, np.array([CHAIR]), _query(cloud), ("chair",), 0.1, EXTENT)
        boxes.append(np.r_[lo[0], hi[0]])
    np.testing.assert_allclose(boxes[1], boxes[0])
    assert 2.2 < boxes[1][3] < 2.3 and 1.7 < boxes[1][0] < 1.8  # the base's 0.56 m, less a few strays
    # the connected part holding most of the box's points
    near = pts[np.all((pts >= [1.5, 1.5, 0.05]) & (pts <= [2.6, 2.5, 1.0]), axis=1)]
    part = element_points(near, np.array([1.5, 1.5, 0.0]), np.array([1.7, 1.7, 0.0]), np.array([2.3, 2.3, 1.0]))
    assert len(part) and part[:, 0].max() < 2.35 and len(part) > 0.5 * len(near)


def test_footprint_settings():
    assert DetectionSettings.from_config().footprint_classes == ("chair",)  # shipped: chairs
    assert DetectionSettings.from_config(footprint_classes="").footprint_classes == ()
    with pytest.raises(ValueError, match="footprint-grow"):
        DetectionSettings(footprint_grow=-0.1)
