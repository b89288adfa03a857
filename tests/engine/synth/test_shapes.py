"""Walls of floors of general polygons, and planning a space in its own frame."""
from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import Polygon, box

from engine.synth.building import Element, Space
from engine.synth.geometry import Box, Poly
from engine.synth.layout import Draft
from engine.synth.shapes import in_local_frame, rotate_xy, walls_from_polygons
from engine.synth.walls import grid_walls

CELLS = {0: (0.0, 0.0, 4.0, 5.0), 1: (4.0, 0.0, 9.0, 5.0), 2: (0.0, 5.0, 9.0, 7.0)}  # two rooms and a hallway


def _spaces():
    return [Space(i, f"s{i}", "office", 0, [c], 0.0, 3.0) for i, c in CELLS.items()]


def _segments(walls):
    out = set()
    for w in walls:
        a, b = np.round(w.p0, 6), np.round(w.p1, 6)
        key = (tuple(a), tuple(b)) if tuple(a) <= tuple(b) else (tuple(b), tuple(a))
        out.add((key, frozenset((w.left, w.right)), w.kind))
    return out


def test_polygon_walls_equal_the_cell_walls():
    spaces = _spaces()
    cell_walls = grid_walls({i: Draft("room", [c]) for i, c in CELLS.items()}, 0, 0.0, spaces,
                        np.random.default_rng(0), 0.3, 0, 9.0, 7.0)
    poly_walls = walls_from_polygons({i: box(*c) for i, c in CELLS.items()}, {}, 0, 0.0, spaces,
                                     lambda key: 0.15, 0.3, 0)
    assert _segments(poly_walls) == _segments(cell_walls)
    for w in poly_walls:  # the space on the left of a wall is on the side of its normal
        if w.right >= 0:
            mid = np.asarray(w.p0) + w.direction * w.length / 2 + w.normal * 0.1
            assert Polygon(box(*CELLS[w.left])).contains(Polygon(box(*(mid - 0.01), *(mid + 0.01))))


def test_walls_turn_with_the_polygons_and_split_at_t_junctions():
    theta = math.radians(27.0)
    polys = {i: Polygon(rotate_xy(np.asarray(box(*c).exterior.coords)[:-1], theta)) for i, c in CELLS.items()}
    walls = walls_from_polygons(polys, {}, 0, 0.0, _spaces(), lambda key: 0.15, 0.3, 0)
    straight = walls_from_polygons({i: box(*c) for i, c in CELLS.items()}, {}, 0, 0.0, _spaces(),
                                   lambda key: 0.15, 0.3, 0)
    assert sorted(round(w.length, 6) for w in walls) == sorted(round(w.length, 6) for w in straight)
    for w in walls:
        a = math.degrees(math.atan2(w.direction[1], w.direction[0])) - 27.0
        assert abs((a + 45.0) % 90.0 - 45.0) < 1e-6
    # the hallway's wall along the two rooms is cut where the rooms meet (a T-junction)
    hall = [w for w in walls if {w.left, w.right} in ({0, 2}, {1, 2})]
    assert len(hall) == 2 and sum(w.length for w in hall) == pytest.approx(9.0)
    # walls on one line share a thickness drawn once per line
    drawn = []
    walls_from_polygons(polys, {}, 0, 0.0, _spaces(), lambda key: drawn.append(key) or 0.1, 0.3, 0)
    assert len(set(drawn)) < len(drawn)


def test_planning_in_the_local_frame_turns_back():
    sp = Space(0, "s", "office", 0, [(0.0, 0.0, 4.0, 3.0)], 0.0, 3.0, axis=math.radians(30.0))
    world = rotate_xy(np.array([[0, 0], [4, 0], [4, 3], [0, 3]], float), sp.axis)
    sp.footprint = world.copy()
    seen = {}

    def plan(walls):
        seen["footprint"] = sp.footprint.copy()
        sp.elements.append(Element(-1, "table", 0, [Box(np.array([2.0, 1.5, 0.4]), np.array([1.0, 0.5, 0.8]), 0.0,
                                                        (1, 1, 1))]))
        sp.elements.append(Element(-1, "floor", 0, [Poly(sp.footprint.copy(), 0.0, True, (1, 1, 1))]))
    in_local_frame(sp, [], plan)
    np.testing.assert_allclose(seen["footprint"], [[0, 0], [4, 0], [4, 3], [0, 3]], atol=1e-12)  # axis-aligned
    np.testing.assert_allclose(sp.footprint, world, atol=1e-12)
    table = sp.elements[0].prims[0]
    assert table.yaw == pytest.approx(sp.axis)
    np.testing.assert_allclose(table.center[:2], rotate_xy(np.array([2.0, 1.5]), sp.axis), atol=1e-12)
    np.testing.assert_allclose(sp.elements[1].prims[0].xy, world, atol=1e-12)
