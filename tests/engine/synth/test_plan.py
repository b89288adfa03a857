"""The plan: deterministic, every space reachable through doors, realistic dimensions, exact room counts."""
from __future__ import annotations

import json
import math

import networkx as nx
import numpy as np
import pytest
from shapely.geometry import Polygon

from engine.synth import plan_building
from tiles.classes import CLASS_CODES
from tiles.errors import UserError


def _doc(b):
    return json.dumps(b.ground_truth(), sort_keys=True)


def test_same_seed_same_plan_other_seed_other_plan():
    a = plan_building(3, area_m2=300, density=100)
    b = plan_building(3, area_m2=300, density=100)
    c = plan_building(4, area_m2=300, density=100)
    assert _doc(a) == _doc(b)
    assert _doc(a) != _doc(c)


@pytest.mark.parametrize("seed,area,floors", [(0, 120, 1), (1, 450, 1), (2, 1400, 1), (3, 900, 2), (4, 3000, 1)])
def test_every_space_reachable_through_doors(seed, area, floors):
    b = plan_building(seed, area_m2=area, floors=floors, density=100)
    doc = b.ground_truth()
    g = nx.Graph()
    g.add_nodes_from(s["id"] for s in doc["spaces"])
    for o in doc["openings"]:
        if o["kind"] == "door" and min(o["spaces"]) >= 0:
            a, c = o["spaces"]
            assert a != c
            g.add_edge(a, c)
    for f in range(floors):
        ids = [s["id"] for s in doc["spaces"] if s["floor"] == f]
        assert nx.is_connected(g.subgraph(ids)), f"floor {f}: spaces cut off"
    assert all(s["doors"] for s in doc["spaces"])
    # the space's neighbours are exactly the other sides of its doors
    for s in doc["spaces"]:
        assert set(s["neighbours"]) == set(g.neighbors(s["id"]))
    if area >= 1400:
        assert sum(s["type"] == "hallway" for s in doc["spaces"]) >= 2  # cross hallways or fire-door segments


@pytest.mark.parametrize("rooms,floors", [(2, 1), (7, 1), (23, 1), (12, 3), (40, 2)])
def test_room_count_is_exact(rooms, floors):
    b = plan_building(1, rooms=rooms, floors=floors, density=100)
    assert len(b.spaces) == rooms
    per_floor = [sum(s.floor == f for s in b.spaces) for f in range(floors)]
    assert max(per_floor) - min(per_floor) <= 1


def test_dimensions_are_realistic(building):
    doc = building.ground_truth()
    for w in doc["walls"]:
        assert 0.1 <= w["thickness"] <= 0.35
        if w["kind"] == "exterior":
            assert w["thickness"] >= 0.25
    for s in doc["spaces"]:
        h = s["z_range"][1] - s["z_range"][0]
        assert 2.6 <= h <= 4.0, s["name"]
        if s["type"] != "hallway":
            ext = np.ptp(np.asarray(s["footprint"]), axis=0)
            assert 1.9 <= ext.min() and ext.max() <= 15.0, (s["name"], ext)
        else:
            assert 1.5 <= np.ptp(np.asarray(s["footprint"]), axis=0).min() <= 2.8
    for o in doc["openings"]:
        wall = doc["walls"][o["wall"]]
        if o["kind"] == "window":
            assert wall["kind"] == "exterior"
        else:
            assert 0.75 <= o["width"] <= 2.0 and 1.9 <= o["height"] <= 2.3
    exterior_doors = [o for o in doc["openings"] if o["kind"] == "door" and -1 in o["spaces"]]
    assert len(exterior_doors) == 1  # the lobby's entrance
    assert doc["spaces"][max(exterior_doors[0]["spaces"])]["type"] == "lobby"


def test_layout_has_hallway_lobby_l_shape_and_open_plan(building):
    types = {s.type for s in building.spaces}
    assert {"hallway", "lobby", "openspace"} <= types
    non_rect = [s for s in building.spaces if abs(Polygon(s.footprint).minimum_rotated_rectangle.area
                                                  - Polygon(s.footprint).area) > 0.5]
    assert non_rect, "no L-shaped space"
    partial = [w for w in building.walls if w.kind == "partial"]
    assert partial and all(w.left == w.right for w in partial)
    owner = building.spaces[partial[0].left]
    assert owner.type == "openspace"
    assert any(e.cls == "wall" and e.info.get("partial") for e in owner.elements)


def test_one_wall_instance_per_face_per_space(building):
    for s in building.spaces:
        faces = [e for e in s.elements if e.cls == "wall" and not e.info.get("partial")]
        assert len(faces) == len(s.footprint)  # one per edge of the clear footprint
        assert sum(e.cls == "floor" for e in s.elements) == 1
        assert sum(e.cls == "ceiling" for e in s.elements) == 1


def test_doors_give_each_side_its_instance(building):
    doc = building.ground_truth()
    els = {e["id"]: e for e in doc["elements"]}
    for o in doc["openings"]:
        sides = [s for s in o["spaces"] if s >= 0]
        assert sorted(els[i]["space"] for i in o["elements"]) == sorted(sides)
        assert all(els[i]["class"] == o["kind"] for i in o["elements"])


def test_floors_stack_with_a_slab_between_them(tower):
    doc = tower.ground_truth()
    f0, f1 = doc["floors"]
    assert 0.2 <= f0["slab"][1] - f0["slab"][0] <= 0.4
    assert f0["ceiling_max"] < f0["slab"][0] <= f0["slab"][1] == pytest.approx(f1["z"])
    for s in doc["spaces"]:
        floor = doc["floors"][s["floor"]]
        assert s["z_range"][0] == pytest.approx(floor["z"])
        assert s["z_range"][1] <= floor["ceiling_max"] + 1e-9
    # the same outline on both floors
    a = [np.asarray(s["footprint"]) for s in doc["spaces"] if s["floor"] == 0]
    b = [np.asarray(s["footprint"]) for s in doc["spaces"] if s["floor"] == 1]
    assert np.allclose(np.concatenate(a).min(0), np.concatenate(b).min(0), atol=0.2)
    assert np.allclose(np.concatenate(a).max(0), np.concatenate(b).max(0), atol=0.2)


def test_elements_have_valid_boxes_and_classes(building):
    doc = building.ground_truth()
    assert [e["id"] for e in doc["elements"]] == list(range(len(doc["elements"])))
    for e in doc["elements"]:
        assert CLASS_CODES[e["class"]] == e["class_code"]
        assert all(v > 0 for v in e["size"])
        assert -math.pi < e["yaw"] <= math.pi
    assert {e["class"] for e in doc["elements"]} == set(CLASS_CODES)
    assert {s["type"] for s in doc["spaces"]} == {"office", "conferenceRoom", "hallway", "lobby", "storage", "WC",
                                                  "openspace"}


@pytest.mark.parametrize("kw,message", [
    ({"area_m2": 10}, "area must be at least"),
    ({"floors": 0}, "floors must be at least 1"),
    ({"rooms": 1}, "rooms must be at least two per floor"),
    ({"area_m2": 200, "density": 0}, "density must be a positive"),
    ({"area_m2": 200, "offset": (0, float("nan"), 0)}, "offset must be three finite"),
])
def test_bad_parameters_are_user_errors(kw, message):
    with pytest.raises(UserError, match=message):
        plan_building(0, **kw)
