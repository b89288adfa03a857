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
