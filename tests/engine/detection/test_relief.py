"""A beam stands out from the ceiling (``relief-classes``, engine/detection/relief.py)."""
from __future__ import annotations

import numpy as np

from engine.detection import moments as mom
from engine.detection.pointindex import PointIndex
from engine.detection.relief import count_in, flat, relief
from engine.detection.settings import DetectionSettings
from tiles.classes import CLASS_CODES


def _room(rng: np.random.Generator, noise: float = 0.0) -> np.ndarray:
    """A 6 x 4 x 3 m room's canonical points: a noisy ceiling at 3 m, walls at x = 0 and x = 6, and a beam
    0.3 m wide and 0.4 m deep along y at x = 3.0-3.3 (its underside and both sides, ``noise`` m off them)."""
    n = 40_000
    ceiling = np.column_stack([rng.uniform(0, 6, n), rng.uniform(0, 4, n), rng.normal(2.99, 0.004, n)])
    ceiling = ceiling[(ceiling[:, 0] < 3.0) | (ceiling[:, 0] > 3.3)]  # hidden by the beam
    walls = [np.column_stack([np.full(n // 2, x), rng.uniform(0, 4, n // 2), rng.uniform(0, 3, n // 2)]) for x in (0.01, 5.99)]
    m = 3000
    under = np.column_stack([rng.uniform(3.0, 3.3, m), rng.uniform(0, 4, m), np.full(m, 2.6)])
    sides = [np.column_stack([np.full(m, x), rng.uniform(0, 4, m), rng.uniform(2.6, 2.99, m)]) for x in (3.0, 3.3)]
    beam = np.concatenate([under, *sides])
    beam[:, 0] += np.where(np.isin(beam[:, 0], (3.0, 3.3)), rng.normal(0, noise, len(beam)), 0)
    beam[:, 2] += np.where(beam[:, 2] == 2.6, rng.normal(0, noise, len(beam)), 0)
    return np.concatenate([ceiling, *walls, beam])


def test_a_beam_stands_out_a_strip_of_ceiling_or_a_walls_top_does_not():
    pts = _room(np.random.default_rng(0))

    def points_in(lo, hi):
        return pts

    beam = relief(np.array([2.98, 0.0, 2.58]), np.array([3.32, 4.0, 3.0]), points_in)
    ceiling_strip = relief(np.array([1.0, 0.0, 2.6]), np.array([1.3, 4.0, 3.0]), points_in)
    wall_top = relief(np.array([0.0, 0.0, 2.6]), np.array([0.3, 4.0, 3.0]), points_in)
    assert beam > 10
    assert ceiling_strip < 1.5  # the same ceiling (nothing, below its top quarter) beside it
    assert wall_top < 1.5  # the wall goes on below it (and nothing beside it in the room)


def test_the_neighbour_boxes_stand_off_a_tight_box():
    """A box fitted to the beam has its faces on the beam's surfaces: half of their points lie beyond them, which
    the boxes beside and below must not count as the surroundings' own."""
    pts = _room(np.random.default_rng(2), noise=0.01)

    def points_in(lo, hi):
        return pts

    lo, hi = np.array([3.0, 0.0, 2.6]), np.array([3.3, 4.0, 3.0])
    assert relief(lo, hi, points_in, gap=0.05) > 10
    assert relief(lo, hi, points_in, gap=0.0) < 3


def test_flat_drops_only_the_classes_asked_for_and_reads_a_point_index():
    pts = _room(np.random.default_rng(1))
    grid = mom.VoxelGrid.covering(np.array([6.0, 4.0, 3.0]), 0.1, 10**6)
    index = PointIndex(pts, grid)
    lo = np.array([[2.98, 0.0, 2.58], [1.0, 0.0, 2.6], [1.0, 0.0, 2.6]])
    hi = np.array([[3.32, 4.0, 3.0], [1.3, 4.0, 3.0], [1.3, 4.0, 3.0]])
    cls = np.array([CLASS_CODES["beam"], CLASS_CODES["beam"], CLASS_CODES["table"]])
    assert flat(cls, lo, hi, index.points_in_metric, ("beam",), 1.5).tolist() == [False, True, False]
    assert not flat(cls, lo, hi, index.points_in_metric, (), 1.5).any()
    # the index's superset, cut to the box, is the exact count
    box = (lo[0], hi[0])
    assert count_in(index.points_in_metric, *box) == int(np.all((pts >= box[0]) & (pts < box[1]), axis=1).sum())


def test_settings_validate_relief():
    assert DetectionSettings().relief_classes == ("beam",)
    for bad in (0.0, -1.0):
        try:
            DetectionSettings(relief_ratio=bad)
        except ValueError as e:
            assert "relief-ratio" in str(e)
        else:
            raise AssertionError("a relief-ratio <= 0 was accepted")
