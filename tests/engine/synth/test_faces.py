"""Wall faces: one instance per footprint edge, a hole per opening, seen from inside; curved runs grouped."""
from __future__ import annotations

import math

import numpy as np
from shapely.geometry import Point, Polygon

from engine.synth.faces import curve_groups, edge_openings, footprint_edges
from engine.synth.geometry import Rect


def test_wall_faces_have_a_hole_per_opening(building):
    for s in building.spaces:
        faces = [e for e in s.elements if e.cls == "wall" and not e.info.get("partial")]
        holes = sum(len(e.prims[0].holes) for e in faces)
        openings = sum(len(edge_openings(s, building.walls, a, b)) for a, b in footprint_edges(s))
        assert holes == openings == len(s.doors) + len(s.windows)
        for e in faces:
            r = e.prims[0]
            assert isinstance(r, Rect)
            # seen from inside: the face normal points into the clear footprint
            n = np.cross(r.u, r.v)
            mid = r.origin + (r.u + r.v) / 2 + 0.05 * n / np.linalg.norm(n)
            assert Polygon(s.footprint).contains(Point(mid[:2]))


def test_edges_turning_a_little_are_one_curved_wall():
    yaws = [0.0, math.radians(10), math.radians(20), math.radians(110), math.radians(200), math.radians(290)]
    faces = [([], y, 1.0) for y in yaws]
    assert curve_groups(faces) == [[0, 1, 2], [3], [4], [5]]
    # a run across the start of the list joins its tail
    yaws = [math.radians(5), math.radians(95), math.radians(185), math.radians(275), math.radians(-5)]
    assert curve_groups([([], y, 1.0) for y in yaws]) == [[4, 0], [1], [2], [3]]
    assert curve_groups([]) == []
