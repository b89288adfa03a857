"""A floor's or ceiling's extent across the room fitted to its slab's points (engine/detection/slabs.py)."""
from __future__ import annotations

import numpy as np
import pytest

from engine.detection.settings import DetectionSettings
from engine.detection.slabs import dense_span, fit_slabs, typical_count
from tiles.classes import ELEMENT_CLASSES

FLOOR, CEILING, CHAIR = (ELEMENT_CLASSES.index(c) for c in ("floor", "ceiling", "chair"))


def _query(points):
    return lambda lo, hi: points[np.all((points >= np.asarray(lo) - 0.1) & (points <= np.asarray(hi) + 0.1), axis=1)]


def _hallway(rng) -> np.ndarray:
    """A 2 x 19 m hallway's floor (2 cm slab), and 300 stray points of the room beyond its wall (x 2.3-4.7 m) at
    the floor's height, as a space that kept a neighbour's clutter holds them."""
    floor = rng.uniform([0.0, 0.0, 0.0], [2.0, 19.0, 0.02], (40000, 3))
    stray = rng.uniform([2.3, 5.0, 0.0], [4.7, 9.0, 0.02], (300, 3))
    return np.concatenate([floor, stray])


def test_a_floor_widened_by_stray_points_shrinks_to_its_own():
    rng = np.random.default_rng(0)
    pts = _hallway(rng)
    lo, hi = np.array([[0.0, 0.0, 0.0]]), np.array([[4.7, 19.0, 0.02]])
    assert fit_slabs(lo, hi, np.array([FLOOR]), _query(pts), ("floor",), 0.02) == 1
    floor = pts[:40000]
    assert np.allclose(lo[0, :2], floor[:, :2].min(axis=0)) and np.allclose(hi[0, :2], floor[:, :2].max(axis=0))
    assert lo[0, 2] == 0.0 and hi[0, 2] == 0.02  # its height is the thin-surface refinement's
    # the same box with the fit off (no classes), or another class's: left alone
    for classes, code in (((), FLOOR), (("floor",), CHAIR)):
        lo2, hi2 = np.array([[0.0, 0.0, 0.0]]), np.array([[4.7, 19.0, 0.02]])
        assert fit_slabs(lo2, hi2, np.array([code]), _query(pts), classes, 0.02) == 0
        assert hi2[0, 0] == 4.7


def test_a_doorway_and_an_l_shaped_floor_stay_in_the_box():
    rng = np.random.default_rng(1)
    room = rng.uniform([0.0, 0.0, 0.0], [4.0, 6.0, 0.02], (30000, 3))
    doorway = rng.uniform([4.0, 2.0, 0.0], [4.2, 2.9, 0.02], (250, 3))  # the floor through a 0.9 m door
    leg = rng.uniform([4.0, 4.0, 0.0], [7.0, 6.0, 0.02], (7500, 3))  # an L's short leg
    for pts, x_end in ((np.concatenate([room, doorway]), 4.2), (np.concatenate([room, leg]), 7.0)):
        lo, hi = np.array([[0.0, 0.0, 0.0]]), np.array([[x_end, 6.0, 0.02]])
        fit_slabs(lo, hi, np.array([FLOOR]), _query(pts), ("floor",), 0.02)
        assert hi[0, 0] == pytest.approx(pts[:, 0].max()) and lo[0, 1] == pytest.approx(pts[:, 1].min())


def test_a_fit_never_grows_a_box_nor_follows_too_few_points():
    rng = np.random.default_rng(2)
    pts = rng.uniform([0.0, 0.0, 0.0], [6.0, 6.0, 0.02], (20000, 3))
    lo, hi = np.array([[1.0, 1.0, 0.0]]), np.array([[3.0, 3.0, 0.02]])  # a window smaller than the floor
    fit_slabs(lo, hi, np.array([FLOOR]), _query(pts), ("floor",), 0.02)
    assert np.all(lo[0] >= [1.0, 1.0, 0.0]) and np.all(hi[0] <= [3.0, 3.0, 0.02])
    few = pts[:50]
    lo, hi = np.array([[0.0, 0.0, 0.0]]), np.array([[6.0, 6.0, 0.02]])
    assert fit_slabs(lo, hi, np.array([FLOOR]), _query(few), ("floor",), 0.02) == 0 and hi[0, 0] == 6.0


def test_a_ceiling_crossed_by_beams_keeps_every_bay():
    """Where a beam meets the ceiling the slab holds no point: the bays beyond are as dense, and stay."""
    rng = np.random.default_rng(3)
    bays = [rng.uniform([x0, 0.0, 2.98], [x1, 5.0, 3.0], (8000, 3)) for x0, x1 in ((0.0, 2.0), (2.3, 4.7), (5.0, 8.0))]
    stray = rng.uniform([8.3, 0.0, 2.98], [9.5, 5.0, 3.0], (12, 3))  # a few points beyond the end wall
    pts = np.concatenate(bays + [stray])
    lo, hi = np.array([[0.0, 0.0, 2.98]]), np.array([[9.5, 5.0, 3.0]])
    fit_slabs(lo, hi, np.array([CEILING]), _query(pts), ("ceiling",), 0.02)
    room = np.concatenate(bays)
    assert lo[0, 0] == pytest.approx(room[:, 0].min()) and hi[0, 0] == pytest.approx(room[:, 0].max())


def test_the_typical_count_is_the_bulks_density():
    assert typical_count(np.array([1000] * 40 + [6] * 48)) == 1000  # many sparse bins do not drag it down
    assert typical_count(np.array([100] * 10 + [5000])) == 5000  # a bin holding most points is the bulk
    assert typical_count(np.array([0, 3, 0])) == 3


def test_the_dense_span_runs_from_the_first_to_the_last_dense_bin():
    values = np.r_[np.linspace(0.01, 0.99, 1000), np.linspace(3.01, 3.39, 2000), [4.02, 4.52]]
    a, b = dense_span(values, 0.0, 0.02)
    assert a == pytest.approx(0.0) and b == pytest.approx(3.4)


def test_settings_validate_the_fraction():
    assert DetectionSettings().slab_classes == ("ceiling", "floor")
    with pytest.raises(ValueError, match="slab-fraction"):
        DetectionSettings(slab_fraction=1.5)
