"""Difficulties in the plan: wing, oblique walls, stairs, thin/thick walls, glass, unscanned rooms, lined walls,
hallway heights, large open spaces -- each present, and the plan still consistent."""
from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from shapely.geometry import Polygon

from engine.synth import plan_building


def _angle_mod90(w) -> float:
    d = w.direction
    return math.degrees(math.atan2(d[1], d[0])) % 90.0


def _close_mod90(a: float, b: float, tol: float = 1e-4) -> bool:
    return abs((a - b + 45.0) % 90.0 - 45.0) < tol


def test_the_wing_is_at_its_angle(hard):
    wing = [s for s in hard.spaces if s.axis != 0.0]
    assert wing and len({round(s.axis, 9) for s in wing}) == 1
    theta = math.degrees(wing[0].axis)
    assert 15.0 <= abs(theta) <= 40.0
    ids = {s.id for s in wing}
    inner = [w for w in hard.walls if w.left in ids and w.right in ids and w.length > 1.0]
    assert inner and all(_close_mod90(_angle_mod90(w), theta % 90.0) for w in inner)
    # the link to the main block has walls at neither frame's angles (diagonal)
    other = [w for w in hard.walls if not _close_mod90(_angle_mod90(w), 0.0) and not
             _close_mod90(_angle_mod90(w), theta % 90.0)]
    assert other
    # the wing lies outside the main block
    main = shapely.union_all([Polygon(s.footprint) for s in hard.spaces if s.axis == 0.0 and s.floor == 0])
    for s in wing:
        assert Polygon(s.footprint).intersection(main).area < 0.01


def test_spaces_of_a_floor_tile_without_overlap(hard):
    for f in range(2):
        polys = [Polygon(s.footprint) for s in hard.spaces if s.floor == f]
        assert all(p.is_valid and p.area > 1.0 for p in polys)
        assert sum(p.area for p in polys) == pytest.approx(shapely.union_all(polys).area, rel=1e-6)
        bodies = shapely.union_all([Polygon(w.body()) for w in hard.walls if w.floor == f and w.kind != "partial"])
        assert all(p.intersection(bodies).area < 0.02 for p in polys)


def test_oblique_walls_chamfer_round_corner_and_slant():
    b = plan_building(2, area_m2=500, density=60, hardness="oblique")
    angles = [_angle_mod90(w) for w in b.walls if w.kind != "partial"]
    assert any(_close_mod90(a, 45.0, 1e-3) for a in angles)  # the chamfer
    odd = [a for a in angles if not _close_mod90(a, 0.0, 1e-3) and not _close_mod90(a, 45.0, 1e-3)]
    assert len(odd) >= 8  # the arc of the rounded corner (and a slanted or curved wall)
    # a curved wall is one wall instance made of several faces
    curved = [e for e in b.elements if e.cls == "wall" and len(e.prims) >= 5]
    assert curved


def test_stairs_rise_through_the_slab(hard):
    towers = sorted((s for s in hard.spaces if s.type == "stairs"), key=lambda s: s.floor)
    assert [s.floor for s in towers] == [0, 1]
    lower, upper = towers
    np.testing.assert_allclose(lower.footprint.min(0), upper.footprint.min(0), atol=1e-6)
    assert lower.z1 == pytest.approx(upper.z0)  # the lower tower space reaches the next floor
    assert hard.floors[0].slab[0] < lower.z1  # ... through the slab
    stair = [e for e in lower.elements if e.info.get("kind") == "stairs"]
    assert len(stair) == 1 and not any(e.info.get("kind") == "stairs" for e in upper.elements)
    tops = sorted(b.center[2] + b.size[2] / 2 for b in stair[0].prims)
    assert tops[0] < lower.z0 + 0.3 and tops[-1] == pytest.approx(upper.z0, abs=1e-6)
    assert len(lower.scanners) == 2 and len(upper.scanners) == 1
    # the tower's walls reach the next floor too
    assert all(hard.walls[w].z1 >= lower.z1 - 1e-9 for w in lower.walls)


def test_thin_and_thick_walls():
    b = plan_building(6, area_m2=700, density=60, hardness={"walls": 2.0})
    t = np.array([w.thickness for w in b.walls if w.kind == "interior"])
    assert (t < 0.1).any() and (t > 0.35).any()
    clean = plan_building(6, area_m2=700, density=60)
    tc = np.array([w.thickness for w in clean.walls if w.kind == "interior"])
    assert tc.min() >= 0.1 and tc.max() <= 0.22


def test_glass_partitions_are_thin_whole_walls_with_glass_doors(hard):
    glass = [w for w in hard.walls if w.material == "glass"]
    assert glass
    for w in glass:
        assert 0.08 <= w.thickness <= 0.12 and w.kind == "interior"
        lo, hi = w.glazing
        assert 0.0 < lo < hi <= w.z1 - w.z0
        # every wall between the same two spaces is glass
        pair = {w.left, w.right}
        assert all(o.material == "glass" for o in hard.walls if {o.left, o.right} == pair and o.kind == "interior")
    doors = [o for w in glass for o in w.openings if o.kind == "door" and o.leaf != "none"]
    for o in doors:
        leaves = [b for e in hard.elements if e.cls == "door" and e.info.get("opening") == o.id for b in e.prims
                  if hasattr(b, "size") and b.density < 0.1]
        assert leaves  # glass leaves


def test_unscanned_rooms_have_no_scanner_and_closed_doors(hard):
    rooms = [s for s in hard.spaces if not s.scanned]
    assert rooms
    for s in rooms:
        assert len(s.scanners) == 0 and s.type in ("storage", "WC", "office")
        doors = [hard.openings[i] for i in s.doors]
        assert doors and all(o.leaf == "closed" for o in doors)
    doc = hard.ground_truth()
    assert {d["id"] for d in doc["spaces"] if not d["scanned"]} == {s.id for s in rooms}


def test_lined_walls_have_tall_cabinets_along_most_of_the_face(hard):
    lined = [w for w in hard.walls if w.lined]
    assert lined
    covered = []
    for w in lined:
        for sid in w.lined:
            sp = hard.spaces[sid]
            cabinets = [e for e in sp.elements if e.info.get("kind") == "cabinet"]
            d, n = w.direction, w.normal
            side = w.side_of(sid)
            span = []
            for e in cabinets:
                c = e.center[:2] - np.asarray(w.p0)
                if abs(abs(float(c @ n)) - (w.thickness / 2 + e.size[1] / 2)) < 0.1 and 0 <= float(c @ d) <= w.length:
                    assert float(c @ n) * side > 0  # on this space's side
                    assert e.size[2] >= 2.0 - 0.02
                    span.append(e.size[0])
            covered.append(sum(span) / w.length)
    assert max(covered) >= 0.6 and np.mean(covered) >= 0.4


def test_hallway_ceilings_above_the_rooms_beside(hard):
    for s in hard.spaces:
        if s.type != "hallway":
            continue
        rooms = {o for w in s.walls for o in (hard.walls[w].left, hard.walls[w].right)} - {s.id, -1}
        beside = [hard.spaces[r] for r in rooms if hard.spaces[r].type in ("office", "storage", "WC")]
        assert all(s.z1 - s.z0 > r.z1 - r.z0 + 0.2 for r in beside)


def test_a_large_open_space_with_columns_and_cubicles():
    b = plan_building(8, area_m2=800, density=60, hardness="open_plan")
    big = max((s for s in b.spaces if s.type == "openspace"), key=lambda s: s.area)
    ext = big.footprint.max(0) - big.footprint.min(0)
    assert max(ext) >= 12.0
    columns = [e for e in big.elements if e.cls == "column" and not e.info.get("engaged")]
    assert len(columns) >= 2 and all(0.4 <= min(e.prims[0].size[:2]) <= 0.8 for e in columns)
    panels = [e for e in big.elements if e.info.get("kind") == "partition"]
    assert panels and all(1.1 <= b.size[2] <= 1.7 for e in panels for b in e.prims)
    assert all(b.center[2] + b.size[2] / 2 < big.z1 - 0.8 for e in panels for b in e.prims)  # they do not divide
