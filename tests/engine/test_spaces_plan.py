"""The plan of a parse after refinement: building faces beside a refined space, and spaces rejoined after it."""
from __future__ import annotations

import numpy as np

from engine.alignment import Frame
from engine.merging import Edge
from engine.refine import Part, Refinement
from engine.slicing import Box
from engine.spaces import _RefinedPlan

BW = 0.01
FRAME = Frame(0.0, (0.0, 0.0, 0.0))


def _box(u0, u1, v0, v1, count=1000):
    return Box(0, int(u0 / BW), int(u1 / BW), int(v0 / BW), int(v1 / BW), final=True, count=count)


def _plan() -> _RefinedPlan:
    """A hallway (u 0-2, v 0-13, not refined) beside a space (u 2-7) that refinement cut into a room (v 0-8)
    and a second room (v 8-13): the one building face between them (u = 2) borders both."""
    cells = [_box(0, 2, 0, 13), _box(2, 7, 0, 13)]
    edges = [Edge(0, 1, 0, 0, 200, (0, 1300))]
    labels = np.array([0, 1])
    part = Part(0.0, cells=[_box(2, 7, 0, 8), _box(2, 7, 8, 13)], labels=np.array([0, 1]),
                edges=[Edge(0, 1, 0, 1, 800, (200, 700), divider={"kind": "peak-gap-peak"})])
    ref = Refinement(1, 0, parts=[part], points=2000)
    return _RefinedPlan.build(cells, edges, labels, [ref], FRAME, BW)


def test_a_building_face_beside_a_refined_space_is_cut_where_the_space_beyond_changes():
    plan = _plan()
    assert plan.n_spaces == 3  # the hallway, then the refinement's two rooms in its place
    building = [(e.overlap, tuple(s)) for e, s, y in zip(plan.edges, plan.sides.tolist(), plan.edge_yaw)
                if (e.a, e.b) == (0, 1)]
    # two pieces, cut within the sampling step (0.25 m) of the rooms' border at v = 8 m
    assert [s for _, s in building] == [(0, 1), (0, 2)]
    (a0, a1), (b0, b1) = building[0][0], building[1][0]
    assert a0 == 0 and a1 == b0 and b1 == 1300 and abs(a1 - 800) <= 25
    # the refinement's own face between its two rooms follows
    assert plan.sides.tolist()[-1] == [1, 2]


def test_regroup_joins_spaces_and_renumbers():
    plan = _plan()
    plan.regroup(np.array([0, 1, 0]))  # the second room joins the hallway
    assert plan.n_spaces == 2
    assert plan.labels.tolist()[:2] == [0, -1]  # the refined space's own cell has no space
    assert plan.labels.tolist()[2:] == [1, 0]
    assert plan.joined == {0: [0, 2]}
    assert plan.sides.tolist() == [[0, 1], [0, 0], [1, 0]]
    assert 0 not in plan.sub_of and plan.sub_of[1][0] == 0
