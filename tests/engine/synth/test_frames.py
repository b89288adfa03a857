"""Door and window elements: a door instance per side with its leaves where they swing, windows with sparse glass."""
from __future__ import annotations

import numpy as np

from engine.synth.geometry import Box, Rect


def test_door_leaves_are_where_they_swing(building):
    for o in building.openings:
        if o.kind != "door" or not o.elements:
            continue
        w = building.walls[o.wall]
        leaf_space = w.left if o.swing > 0 else w.right
        for eid in o.elements:
            e = building.elements[eid]
            leaves = [p for p in e.prims if isinstance(p, Box) and abs(p.size[1] - 0.04) < 1e-9]
            if o.leaf == "none":
                assert not leaves
            elif o.leaf == "closed":
                assert len(leaves) == o.leaves  # both sides see their face of a closed leaf
            else:
                assert len(leaves) == (o.leaves if e.space == leaf_space else 0)
                for lf in leaves:  # an open leaf stands in its room, not in the wall
                    off = (lf.center[:2] - np.asarray(w.p0)) @ w.normal * w.side_of(leaf_space)
                    assert off > w.thickness / 2


def test_windows_are_on_exterior_walls_with_sparse_glass(building):
    for o in building.openings:
        if o.kind != "window":
            continue
        w = building.walls[o.wall]
        assert w.kind == "exterior" and len(o.elements) == 1
        e = building.elements[o.elements[0]]
        glass = [p for p in e.prims if isinstance(p, Rect) and p.density < 1]
        assert len(glass) == 1 and glass[0].density <= 0.2


def test_door_types_are_one_per_door_and_their_boxes_hold_their_points(helpers):
    from collections import Counter

    from engine.synth import plan_building, scan_building
    from engine.synth.frames import DOOR_TYPES, door_type

    assert {door_type(5, i) for i in range(100)} == set(DOOR_TYPES)
    classic, styled = (plan_building(23, area_m2=300, density=100, styles=s) for s in ("classic", "doors"))
    assert [(o.kind, o.s0, o.s1) for o in styled.openings] == [(o.kind, o.s0, o.s1) for o in classic.openings]
    doors = [e for s in styled.spaces for e in s.elements if e.cls == "door"]
    by_opening = {}
    for e in doors:  # both sides of a door are of one type
        assert by_opening.setdefault(e.info["opening"], e.info["type"]) == e.info["type"]
    assert len(Counter(by_opening.values())) >= 3
    plain = {e.info["opening"]: e for s in classic.spaces for e in s.elements if e.cls == "door"}
    for e in doors:
        if e.info["type"] == "flush":  # no casing: fewer parts than the classic door
            assert len(e.prims) < len(plain[e.info["opening"]].prims)
    scan = scan_building(styled)
    P = helpers.xyz(scan)
    for g in styled.ground_truth()["elements"]:
        sel = scan["gt_instance"] == g["id"]
        assert helpers.in_box(P[sel], g, grow=1e-6).all(), g["class"]
