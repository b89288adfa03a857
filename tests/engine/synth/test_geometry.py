"""Primitives: outward faces, rectangles seen from the asked side, tight oriented bounds."""
from __future__ import annotations

import math

import numpy as np
import pytest

from engine.synth.geometry import Box, oriented_bounds, rect


def test_box_faces_point_outwards_and_cover_the_surface():
    b = Box(np.array([1.0, 2.0, 0.5]), np.array([0.8, 0.4, 1.0]), 0.7, (0, 0, 0))
    faces = b.faces()
    assert len(faces) == 6
    assert sum(f.area for f in faces) == pytest.approx(2 * (0.8 * 0.4 + 0.4 * 1.0 + 0.8 * 1.0))
    for f in faces:
        centre = f.origin + (f.u + f.v) / 2
        normal = np.cross(f.u, f.v)
        assert np.dot(normal, centre - b.center) > 0
    # standing on the floor: no bottom face; touching the ceiling: no top face either
    assert len(b.faces(floor_z=0.0)) == 5 and len(b.faces(floor_z=0.0, ceiling_z=1.0)) == 4


def test_rect_is_seen_from_the_asked_side_and_keeps_its_holes():
    r = rect([0, 0, 0], [2, 0, 0], [0, 0, 3], [0, 1, 0], (1, 2, 3), holes=[(0.5, 1.0, 0.0, 2.0)])
    assert np.dot(np.cross(r.u, r.v), [0, 1, 0]) > 0
    # u and v were swapped: the hole follows (s along u = z now)
    assert r.holes == [(0.0, 2.0, 0.5, 1.0)]
    same = rect([0, 0, 0], [2, 0, 0], [0, 0, 3], [0, -1, 0], (1, 2, 3), holes=[(0.5, 1.0, 0.0, 2.0)])
    assert same.holes == [(0.5, 1.0, 0.0, 2.0)]


def test_oriented_bounds_of_a_turned_box_are_its_own_size():
    b = Box(np.array([3.0, -1.0, 2.0]), np.array([1.2, 0.5, 0.3]), 0.9, (0, 0, 0))
    centre, size = oriented_bounds(b.corners(), 0.9)
    np.testing.assert_allclose(centre, b.center, atol=1e-12)
    np.testing.assert_allclose(size, b.size, atol=1e-12)
    _, axis_aligned = oriented_bounds(b.corners(), 0.0)
    c, s = abs(math.cos(0.9)), abs(math.sin(0.9))
    np.testing.assert_allclose(axis_aligned, [1.2 * c + 0.5 * s, 1.2 * s + 0.5 * c, 0.3], atol=1e-12)
