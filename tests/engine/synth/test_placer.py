"""The placer: pieces inside the footprint, never in each other, against walls facing into the room."""
from __future__ import annotations

import math

import numpy as np

from engine.synth.building import Space
from engine.synth.placer import Placer


def _room(cells=((0.0, 0.0, 4.0, 3.0),), footprint=None) -> Space:
    s = Space(0, "office_1", "office", 0, list(cells), 0.0, 2.8)
    s.footprint = np.array(footprint if footprint is not None else [[0, 0], [4, 0], [4, 3], [0, 3]], float)
    return s


BOX = [(0, 0, 0.5, 1.0, 0.6, 1.0, (1, 2, 3))]


def test_a_piece_is_kept_inside_and_apart():
    s = _room()
    p = Placer(np.random.default_rng(0), s, [], {})
    assert p.rectangular
    el = p.put("table", BOX, (2.0, 1.5), 0.0)
    assert el is not None and s.elements == [el] and el.space == 0
    assert p.put("table", BOX, (2.3, 1.5), 0.0) is None  # in the first one
    assert p.put("table", BOX, (3.9, 1.5), 0.0) is None  # through the wall
    assert p.put("table", BOX, (3.2, 1.5), 0.0) is not None
    assert len(s.elements) == 2


def test_a_turned_piece_is_set_down_turned():
    s = _room()
    p = Placer(np.random.default_rng(0), s, [], {})
    boxes = p.build([(1.0, 0.0, 0.5, 0.2, 0.2, 1.0, (0, 0, 0))], (2.0, 1.5), math.pi / 2, z=0.5)
    assert np.allclose(boxes[0].center, [2.0, 2.5, 1.0])
    assert boxes[0].yaw == math.pi / 2


def test_an_l_shaped_room_refuses_its_missing_corner():
    s = _room([(0.0, 0.0, 4.0, 2.0), (0.0, 2.0, 2.0, 4.0)], [[0, 0], [4, 0], [4, 2], [2, 2], [2, 4], [0, 4]])
    p = Placer(np.random.default_rng(0), s, [], {})
    assert not p.rectangular
    assert p.put("table", BOX, (3.0, 3.0), 0.0) is None
    assert p.put("table", BOX, (1.0, 3.0), 0.0) is not None


def test_against_a_wall_the_back_is_at_the_wall_and_the_front_faces_in():
    s = _room()
    p = Placer(np.random.default_rng(3), s, [], {})
    for _ in range(5):
        el = p.against_wall("bookcase", lambda: [(0, 0, 1.0, 0.8, 0.4, 2.0, (0, 0, 0))], 0.8, 0.4, 2.0, gap=0.0)
        assert el is not None
        b = el.prims[0]
        back = b.center[:2] + np.array([-math.sin(b.yaw), math.cos(b.yaw)]) * 0.2  # local +y, the back
        front = b.center[:2] - np.array([-math.sin(b.yaw), math.cos(b.yaw)]) * 0.2
        dist = lambda q: min(q[0], 4 - q[0], q[1], 3 - q[1])  # noqa: E731
        assert dist(back) < 1e-6 and dist(front) > 0.39
