"""Walls on grid lines: one where two spaces (or a space and the outside) meet, one thickness per line."""
from __future__ import annotations

import numpy as np

from engine.synth.building import Space
from engine.synth.layout import Draft
from engine.synth.walls import grid_walls, thickness_draw

CELLS = {0: (0.0, 0.0, 4.0, 5.0), 1: (4.0, 0.0, 9.0, 5.0), 2: (0.0, 5.0, 9.0, 7.0)}  # two rooms and a hallway


def test_walls_where_spaces_meet_with_the_left_space_on_the_left():
    spaces = [Space(i, f"s{i}", "office", 0, [c], 0.0, 3.0 + i / 10) for i, c in CELLS.items()]
    walls = grid_walls({i: Draft("room", [c]) for i, c in CELLS.items()}, 0, 0.0, spaces,
                       np.random.default_rng(0), 0.3, 10, 9.0, 7.0)
    interior = [w for w in walls if w.kind == "interior"]
    assert sorted(tuple(sorted((w.left, w.right))) for w in interior) == [(0, 1), (0, 2), (1, 2)]
    assert all(w.thickness == 0.3 for w in walls if w.kind == "exterior")
    assert all(0.1 <= w.thickness <= 0.22 for w in interior)
    # the two rooms' walls to the hallway are on one line: one thickness
    assert len({w.thickness for w in interior if 2 in (w.left, w.right)}) == 1
    assert [w.id for w in walls] == list(range(10, 10 + len(walls)))
    for w in walls:
        assert w.z1 == max(spaces[s].z1 for s in (w.left, w.right) if s >= 0)
        if w.left >= 0:  # the left space is on the side of the wall's normal
            mid = (np.asarray(w.p0) + np.asarray(w.p1)) / 2 + 0.1 * w.normal
            x0, y0, x1, y1 = CELLS[w.left]
            assert x0 < mid[0] < x1 and y0 < mid[1] < y1


def test_a_thickness_is_drawn_once_per_line():
    draw = thickness_draw(np.random.default_rng(0))
    a = draw(("interior", 1, 5.0))
    assert draw(("interior", 1, 5.0)) == a and 0.1 <= a <= 0.22
    assert all(0.1 <= draw(("partial", k)) <= 0.15 for k in range(20))
