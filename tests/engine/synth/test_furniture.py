"""Furniture: inside the room, not in each other, out of doorways; what each room type holds."""
from __future__ import annotations

from collections import Counter

import numpy as np
from shapely.geometry import MultiPoint, Polygon

from engine.synth import plan_building
from engine.synth.geometry import Box

FURNITURE = ("table", "chair", "sofa", "bookcase", "board")


def test_pieces_stand_inside_their_room_and_apart(building):
    for s in building.spaces:
        poly = Polygon(s.footprint).buffer(1e-6)
        placed = [e for e in s.elements if e.cls in FURNITURE or (e.cls == "clutter" and e.info.get("kind") != "light")]
        for e in placed:
            corners = np.concatenate([p.corners() for p in e.prims])
            assert poly.contains(MultiPoint(corners[:, :2]).convex_hull), (s.name, e.cls)
            assert corners[:, 2].min() >= s.z0 - 1e-9 and corners[:, 2].max() <= s.z1 + 1e-9
        parts = [(k, p) for k, e in enumerate(placed) for p in e.prims]
        lo = np.array([p.corners().min(0) for _, p in parts])
        hi = np.array([p.corners().max(0) for _, p in parts])
        owner = np.array([k for k, _ in parts])
        for i in range(len(parts)):  # parts of different pieces never overlap (axis-aligned bounds)
            inter = np.minimum(hi[i], hi) - np.maximum(lo[i], lo)
            clash = np.all(inter > 0.005, axis=1) & (owner != owner[i])
            assert not clash.any(), (s.name, placed[owner[i]].cls, placed[owner[np.argmax(clash)]].cls)


def test_doorways_stay_clear(building):
    walls = building.walls
    for s in building.spaces:
        pieces = [p for e in s.elements if e.cls in FURNITURE for p in e.prims]
        for oid in s.doors:
            o = building.openings[oid]
            w = walls[o.wall]
            side = w.side_of(s.id)
            a = np.asarray(w.p0) + w.direction * o.s0 + w.normal * side * w.thickness / 2
            b = np.asarray(w.p0) + w.direction * o.s1 + w.normal * side * w.thickness / 2
            zone = Polygon([a, b, b + w.normal * side * 0.9, a + w.normal * side * 0.9])
            for p in pieces:
                foot = MultiPoint(p.corners()[:, :2]).convex_hull
                assert foot.intersection(zone).area < 1e-4, (s.name, "blocks a door")


def test_room_types_hold_their_furniture():
    b = plan_building(2, area_m2=2500, density=100)
    kinds: dict[str, Counter] = {}
    for s in b.spaces:
        c = Counter(e.cls for e in s.elements)
        kinds.setdefault(s.type, Counter()).update(c)
        if s.type == "conferenceRoom":
            assert c["table"] >= 1 and c["chair"] >= 2 and c["board"] >= 1, s.name
        if s.type == "WC":
            assert not any(c[k] for k in FURNITURE), s.name
            assert any(e.info.get("kind") == "toilet" for e in s.elements) or \
                any(e.info.get("kind") == "sink" for e in s.elements)
        if s.type == "storage":
            assert c["bookcase"] + c["clutter"] >= 3
    assert kinds["office"]["table"] >= kinds["office"]["chair"] * 0.5 > 0
    assert kinds["openspace"]["table"] >= 4
    assert kinds["lobby"]["sofa"] >= 1
    assert all(isinstance(p, Box) for s in b.spaces for e in s.elements if e.cls in FURNITURE for p in e.prims)
