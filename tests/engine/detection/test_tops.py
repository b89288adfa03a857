"""A solid element's top fitted to its points (engine/detection/tops.py)."""
from __future__ import annotations

import numpy as np
import pytest

from engine.detection.settings import DetectionSettings
from engine.detection.tops import fit_tops
from tiles.classes import ELEMENT_CLASSES

BOOKCASE = ELEMENT_CLASSES.index("bookcase")
EXTENT = np.array([6.0, 5.0, 3.0])  # the space: 3 m high


def _bookcase(rng, top: float) -> np.ndarray:
    """A 1.0 x 0.4 m bookcase against the wall y = 0 of a room, its front at y = 0.4: shelves every 0.35 m and books
    on them seen from the front, side panels, up to ``top``; the wall behind and the ceiling above."""
    front = rng.uniform([1.0, 0.38, 0.0], [2.0, 0.4, top], (4000, 3))
    shelves = np.concatenate([rng.uniform([1.0, 0.0, z - 0.01], [2.0, 0.4, z + 0.01], (300, 3))
                              for z in np.arange(0.0, top, 0.35)] + [rng.uniform([1.0, 0.0, top - 0.02], [2.0, 0.4, top], (300, 3))])
    wall = rng.uniform([0.0, 0.0, 0.0], [6.0, 0.005, 3.0], (20000, 3))
    ceiling = rng.uniform([0.0, 0.0, 2.995], [6.0, 5.0, 3.0], (20000, 3))
    return np.concatenate([front, shelves, wall, ceiling])


def _query(points):
    return lambda lo, hi: points[np.all((points >= np.asarray(lo) - 0.1) & (points <= np.asarray(hi) + 0.1), axis=1)]


def test_a_bookcase_taller_than_its_box_gets_its_points_top():
    rng = np.random.default_rng(0)
    pts = _bookcase(rng, 2.15)
    lo, hi = np.array([[1.0, 0.0, 0.0]]), np.array([[2.0, 0.4, 1.8]])
    fit_tops(lo, hi, np.array([BOOKCASE]), _query(pts), ("bookcase",), 0.6, EXTENT)
    assert abs(hi[0, 2] - 2.15) < 0.01 and lo[0, 2] == 0.0
    # a box taller than the points comes down to them
    hi2 = np.array([[2.0, 0.4, 2.6]])
    fit_tops(lo.copy(), hi2, np.array([BOOKCASE]), _query(pts), ("bookcase",), 0.6, EXTENT)
    assert abs(hi2[0, 2] - 2.15) < 0.01
    # other classes, or no classes, are left alone
    hi3 = np.array([[2.0, 0.4, 1.8]])
    fit_tops(lo.copy(), hi3, np.array([ELEMENT_CLASSES.index("table")]), _query(pts), ("bookcase",), 0.6, EXTENT)
    assert hi3[0, 2] == 1.8


def test_columns_that_run_on_to_the_ceiling_say_nothing():
    rng = np.random.default_rng(1)
    # a partition inside the footprint, floor to ceiling: its columns are left out, the others give the top
    pts = np.concatenate([_bookcase(rng, 2.15), rng.uniform([1.4, 0.1, 0.0], [1.42, 0.3, 3.0], (6000, 3))])
    lo, hi = np.array([[1.0, 0.0, 0.0]]), np.array([[2.0, 0.4, 1.8]])
    fit_tops(lo, hi, np.array([BOOKCASE]), _query(pts), ("bookcase",), 0.6, EXTENT)
    assert abs(hi[0, 2] - 2.15) < 0.01
    # shelves up to the ceiling: every column runs on, nothing shows where the element ends
    tall = _bookcase(rng, 3.0)
    hi = np.array([[2.0, 0.4, 2.5]])
    fit_tops(lo, hi, np.array([BOOKCASE]), _query(tall), ("bookcase",), 0.6, EXTENT)
    assert hi[0, 2] == 2.5


def test_top_settings():
    assert DetectionSettings.from_config().top_classes == ("bookcase",)
    assert DetectionSettings.from_config(top_classes="").top_classes == ()
    with pytest.raises(ValueError, match="top-reach"):
        DetectionSettings(top_reach=-1.0)
