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


def _boxes(b):
    """Per space, its elements' classes and box centres (their sizes hold the room's scan noise, varied too)."""
    return {s.id: sorted((e.cls, tuple(np.round(e.center, 9))) for e in s.elements) for s in b.spaces}


def test_varied_styles_change_boards_and_scan_character_only_and_hold_their_points(helpers):
    from engine.synth import scan_building

    classic, varied = (plan_building(13, area_m2=300, density=150, styles=s) for s in ("classic", "varied"))
    assert _boxes(classic) == _boxes(plan_building(13, area_m2=300, density=150))  # classic is the default
    assert "styles" not in classic.params and varied.params["styles"] == "varied"
    boards = [e for s in varied.spaces for e in s.elements if e.cls == "board"]
    # the same plan; a room's furniture moves only where a bare board left it room
    assert [s.footprint.tolist() for s in varied.spaces] == [s.footprint.tolist() for s in classic.spaces]
    bare = {e.space for e in boards if e.info["style"] == "bare"}
    a, b = _boxes(classic), _boxes(varied)
    assert bare and all(a[k] == b[k] for k in a if k not in bare)
    noise = [s.noise for s in varied.spaces]
    assert min(noise) < 0.002 or max(noise) > 0.006  # beyond the classic 2-6 mm
    # both families, recorded in the ground truth: bare (1-4 cm) and with a tray (0.1 m placement box)
    assert {e.info["style"] for e in boards} == {"bare", "tray"}
    assert all(0.01 <= e.info["thickness"] <= 0.04 for e in boards if e.info["style"] == "bare")
    assert all(not e.info for s in classic.spaces for e in s.elements if e.cls == "board")
    scan = scan_building(varied)
    P = helpers.xyz(scan)
    doc = {e["id"]: e for e in varied.ground_truth()["elements"]}
    assert {doc[e.id]["style"] for e in boards} == {"bare", "tray"}
    for e in boards:
        sel = scan["gt_instance"] == e.id
        assert sel.any() and helpers.in_box(P[sel], doc[e.id], grow=1e-6).all()
        assert np.all(scan["gt_class"][sel] == doc[e.id]["class_code"])
    for e in doc.values():  # every box holds its points, whatever the room's noise
        sel = scan["gt_instance"] == e["id"]
        assert helpers.in_box(P[sel], e, grow=1e-6).all(), e["class"]
