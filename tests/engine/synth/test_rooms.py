"""Room types and heights: circulation keeps its type, small drafts become small rooms, big floors get a WC."""
from __future__ import annotations

from collections import defaultdict

import numpy as np

from engine.synth.building import Space
from engine.synth.layout import Draft
from engine.synth.rooms import ensure_wc, new_space, room_type


def test_circulation_keeps_its_type_and_small_rooms_are_small_types():
    rng = np.random.default_rng(0)
    for t in ("hallway", "lobby", "openspace", "stairs"):
        assert room_type(rng, Draft(t, [(0, 0, 10, 2)])) == t
    small = {room_type(rng, Draft("room", [(0, 0, 3, 3)])) for _ in range(50)}
    assert small == {"storage", "WC", "office"}
    big = {room_type(rng, Draft("room", [(0, 0, 8, 6)])) for _ in range(200)}
    assert "conferenceRoom" in big


def test_new_spaces_are_named_by_type_and_hallways_are_lower_lobbies_higher():
    counters: dict[str, int] = defaultdict(int)
    rng = np.random.default_rng(1)
    a = new_space(Draft("hallway", [(0, 0, 10, 2)]), 0, 0, 0.0, 3.0, rng, counters)
    b = new_space(Draft("hallway", [(0, 2, 10, 4)]), 1, 0, 0.0, 3.0, rng, counters)
    c = new_space(Draft("lobby", [(10, 0, 16, 6)]), 2, 0, 0.0, 3.0, rng, counters)
    assert (a.name, b.name, c.name) == ("hallway_1", "hallway_2", "lobby_1")
    assert 2.7 <= a.z1 <= 3.0 and 3.3 <= c.z1 <= 3.9


def test_a_floor_of_five_rooms_gets_its_wc_from_the_smallest_office():
    sizes = [4.0, 3.0, 5.0, 6.0, 4.5]
    spaces = [Space(i, f"office_{i + 1}", "office", 0, [(0.0, 0.0, w, 3.0)], 0.0, 3.0) for i, w in enumerate(sizes)]
    spaces.append(Space(5, "hallway_1", "hallway", 0, [(0.0, 3.0, 20.0, 5.0)], 0.0, 3.0))
    counters: dict[str, int] = defaultdict(int, office=5)
    ensure_wc(spaces, counters)
    assert [s.type for s in spaces] == ["office", "WC", "office", "office", "office", "hallway"]
    assert spaces[1].name == "WC_1"
    ensure_wc(spaces[:4], counters)  # four rooms: no WC needed
    assert sum(s.type == "WC" for s in spaces) == 1
