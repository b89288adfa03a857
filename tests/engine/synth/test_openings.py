"""Doors and windows of a floor: every space reachable, doors clear of the joints, windows on exterior walls."""
from __future__ import annotations

import networkx as nx
import numpy as np
import pytest
from shapely.geometry import box

from engine.synth import colours, plan_building
from engine.synth.building import Space, Wall
from engine.synth.layout import Draft
from engine.synth.openings import door_room, place_doors, place_windows
from engine.synth.shapes import clear_footprints
from engine.synth.walls import grid_walls

# a hallway along the bottom, three offices above it, a storage room reachable only through the last office
CELLS = {0: ("hallway", (0.0, 0.0, 12.0, 2.0)), 1: ("office", (0.0, 2.0, 4.0, 6.0)),
         2: ("office", (4.0, 2.0, 8.0, 6.0)), 3: ("office", (8.0, 2.0, 12.0, 6.0)),
         4: ("storage", (8.0, 6.0, 12.0, 9.0))}


def _floor(seed: int):
    spaces = [Space(i, f"{t}_{i}", t, 0, [c], 0.0, 3.0) for i, (t, c) in CELLS.items()]
    drafts = {i: Draft(t, [c]) for i, (t, c) in CELLS.items()}
    walls = grid_walls(drafts, 0, 0.0, spaces, np.random.default_rng(seed), 0.3, 0, 12.0, 9.0)
    clear_footprints({i: box(*c) for i, (_, c) in CELLS.items()}, walls, spaces)
    return spaces, drafts, walls


def test_door_room_keeps_the_door_clear_of_the_joints():
    w = Wall(0, 0, (0.0, 0.0), (3.0, 0.0), 0.2, 0.0, 3.0, 0, 1, "interior")
    lo, hi = door_room(w, 1.0)
    assert lo == pytest.approx(max(w.ext0, 0.05) + 0.18 + 0.5) and hi == pytest.approx(3.0 - max(w.ext1, 0.05) - 0.68)
    assert door_room(w, 2.8) is None


@pytest.mark.parametrize("seed", range(5))
def test_every_space_is_reachable_and_doors_fit_their_walls(seed):
    spaces, drafts, walls = _floor(seed)
    openings: list = []
    place_doors(np.random.default_rng(seed), walls, spaces, openings, drafts, exterior_door=True, closed={4})
    g = nx.Graph()
    g.add_nodes_from(drafts)
    for o in openings:
        w = walls[o.wall]
        assert o.kind == "door" and o in w.openings and o.id == openings.index(o)
        assert w.ext0 <= o.s0 < o.s1 <= w.length - w.ext1 and o.z1 <= 3.0 - 0.25 + 1e-9
        if w.kind == "interior":
            g.add_edge(w.left, w.right)
            if 4 in (w.left, w.right):
                assert o.leaf == "closed"
            if spaces[w.left].type == "hallway" or spaces[w.right].type == "hallway":
                room = w.right if spaces[w.left].type == "hallway" else w.left
                assert w.side_of(room) == o.swing  # leaves swing into the room
    assert nx.is_connected(g)
    exterior = [o for o in openings if walls[o.wall].kind == "exterior"]
    assert len(exterior) == 1 and 0 in (walls[exterior[0].wall].left, walls[exterior[0].wall].right)


def test_windows_are_spaced_on_exterior_walls_off_the_doors():
    spaces, drafts, walls = _floor(0)
    openings: list = []
    place_doors(np.random.default_rng(0), walls, spaces, openings, drafts, exterior_door=True)
    n_doors = len(openings)
    style = colours.building_style(np.random.default_rng(0))
    place_windows(np.random.default_rng(0), walls, spaces, openings, style)
    windows = openings[n_doors:]
    assert windows and all(o.kind == "window" and walls[o.wall].kind == "exterior" for o in windows)
    for o in windows:
        w = walls[o.wall]
        assert o.z0 == pytest.approx(w.z0 + style["sill"], abs=1e-4) and o.z1 <= 3.0 - 0.3 + 1e-9
        for d in w.openings:
            if d.kind == "door":
                assert o.s1 + 0.3 <= d.s0 or o.s0 >= d.s1 + 0.3


def test_window_types_differ_per_wall_and_ribbons_run_between_the_doors():
    from engine.synth.openings import window_type

    types = [window_type(7, w) for w in range(200)]
    assert {t["type"] for t in types} == {"punched", "ribbon", "full", "tall"}
    assert all(t["sill"] <= 0.15 and not t["sill_board"] for t in types if t["type"] == "full")
    assert all(t["mullion"] > 0 for t in types if t["type"] == "ribbon")
    assert {t["sill_board"] for t in types} == {True, False}
    assert window_type(7, 3) == window_type(7, 3) != window_type(8, 3)
    spaces, drafts, walls = _floor(0)
    openings: list = []
    place_doors(np.random.default_rng(0), walls, spaces, openings, drafts, exterior_door=True)
    n_doors = len(openings)
    style = dict(colours.building_style(np.random.default_rng(0)), windows=7)
    place_windows(np.random.default_rng(0), walls, spaces, openings, style)
    windows = openings[n_doors:]
    assert windows
    for o in windows:
        w, t = walls[o.wall], window_type(7, o.wall)
        assert o.style == t["type"] and o.sill_board == t["sill_board"] and o.mullion == pytest.approx(t["mullion"])
        assert o.z0 == pytest.approx(w.z0 + t["sill"], abs=1e-4) and o.z1 - o.z0 >= 0.5
        for d in w.openings:
            if d.kind == "door":
                assert o.s1 + 0.3 <= d.s0 + 1e-9 or o.s0 >= d.s1 + 0.3 - 1e-9


def test_a_windows_building_keeps_its_spaces_and_its_windows_boxes_hold_their_points(helpers):
    from engine.synth import scan_building

    classic, styled = (plan_building(21, area_m2=260, density=120, styles=s) for s in ("classic", "windows"))
    assert styled.params["styles"] == "windows"
    assert [s.footprint.tolist() for s in styled.spaces] == [s.footprint.tolist() for s in classic.spaces]
    windows = [e for s in styled.spaces for e in s.elements if e.cls == "window"]
    assert len({e.info["type"] for e in windows}) >= 2
    assert all("type" not in e.info for s in classic.spaces for e in s.elements if e.cls == "window")
    scan = scan_building(styled)
    P = helpers.xyz(scan)
    for e in styled.ground_truth()["elements"]:
        sel = scan["gt_instance"] == e["id"]
        assert helpers.in_box(P[sel], e, grow=1e-6).all(), e["class"]
