"""Scan positions: inside the space, 1.35-1.65 m high, never inside furniture."""
from __future__ import annotations

import numpy as np
from shapely.geometry import Point, Polygon

from engine.synth.geometry import Box


def test_scanners_are_inside_and_clear(building):
    poly_of = {s.id: Polygon(s.footprint) for s in building.spaces}
    for s in building.spaces:
        assert len(s.scanners) >= 1
        for x, y, z in s.scanners:
            assert poly_of[s.id].contains(Point(x, y)) and 1.35 <= z - s.z0 <= 1.65
            for e in s.elements:  # never inside furniture
                for p in e.prims:
                    if isinstance(p, Box) and p.center[2] - p.size[2] / 2 < z < p.center[2] + p.size[2] / 2:
                        local = (np.array([x, y, z]) - p.center) @ p.axes().T
                        assert np.any(np.abs(local) > p.size / 2)
