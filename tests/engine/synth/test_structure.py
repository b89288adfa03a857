"""Structure of a space: wall faces with holes at openings, doors per side, windows, columns, beams, scanners."""
from __future__ import annotations

import numpy as np
from shapely.geometry import Point, Polygon

from engine.synth.faces import edge_openings, footprint_edges
from engine.synth.geometry import Box, Rect


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


def test_columns_beams_and_scanners(building):
    poly_of = {s.id: Polygon(s.footprint) for s in building.spaces}
    kinds = set()
    for s in building.spaces:
        for e in s.elements:
            if e.cls == "column":
                b = e.prims[0]
                assert b.size[2] == s.z1 - s.z0  # floor to ceiling
                kinds.add("engaged" if e.info.get("engaged") else "free")
            if e.cls == "beam":
                b = e.prims[0]
                assert b.center[2] + b.size[2] / 2 == s.z1  # under the ceiling, above the doors
                assert b.center[2] - b.size[2] / 2 > max([building.openings[i].z1 for i in s.doors] + [s.z0 + 2.0])
        assert len(s.scanners) >= 1
        for x, y, z in s.scanners:
            assert poly_of[s.id].contains(Point(x, y)) and 1.35 <= z - s.z0 <= 1.65
            for e in s.elements:  # never inside furniture
                for p in e.prims:
                    if isinstance(p, Box) and p.center[2] - p.size[2] / 2 < z < p.center[2] + p.size[2] / 2:
                        local = (np.array([x, y, z]) - p.center) @ p.axes().T
                        assert np.any(np.abs(local) > p.size / 2)
    assert kinds == {"engaged", "free"}
