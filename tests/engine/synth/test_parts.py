"""Scan tasks: a space too big for one task is cut into slabs that cover it; estimates count every face."""
from __future__ import annotations

import math

import numpy as np
import pytest

from engine.synth.building import Element, Space
from engine.synth.geometry import Box
from engine.synth.parts import estimate_points, plan_parts


def test_estimate_counts_every_face_of_a_box_at_the_density():
    s = Space(0, "office_1", "office", 0, [(0.0, 0.0, 4.0, 3.0)], 0.0, 3.0, density=2.0)
    s.elements.append(Element(-1, "column", 0, [Box(np.zeros(3), np.array([1.0, 2.0, 3.0]), 0.0, (0, 0, 0))]))
    assert estimate_points(s, 10.0) == pytest.approx(2 * (2 + 6 + 3) * 10.0 * 2.0)


def test_big_spaces_are_cut_into_slabs_along_their_long_side(building):
    est = {s.id: estimate_points(s, building.density) for s in building.spaces}
    part_points = int(max(est.values()) / 3)
    parts = plan_parts(building, part_points)
    assert [p.part_id for p in parts] == list(range(len(parts)))
    for s in building.spaces:
        mine = [p for p in parts if p.space == s.id]
        assert len(mine) == max(1, math.ceil(est[s.id] / part_points)) == mine[0].pieces
        assert mine[0].lo == -math.inf and mine[-1].hi == math.inf
        assert all(a.hi == b.lo for a, b in zip(mine[:-1], mine[1:]))
        ext = s.footprint.max(0) - s.footprint.min(0)
        assert all(p.axis == int(np.argmax(ext)) for p in mine)
    assert len(parts) > len(building.spaces)
