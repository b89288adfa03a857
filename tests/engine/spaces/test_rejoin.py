"""Rejoining refined pieces with their neighbours beyond the refined space (engine.spaces.rejoin)."""
from __future__ import annotations

import numpy as np

from engine.spaces.merging import Edge, MergeRules
from engine.spaces.rejoin import rejoin_pieces
from engine.spaces.slicing import Box

BW = 0.01


def _cell(u0, u1, v0, v1, count=None):
    b = [int(round(x / BW)) for x in (u0, u1, v0, v1)]
    area = (u1 - u0) * (v1 - v0)
    return Box(0, b[0], b[1], b[2], b[3], final=True, count=int(100 * area) if count is None else count)


def _edge(a, b, axis, pos, o0, o1, divider=None):
    return Edge(a, b, 0, axis, int(round(pos / BW)), (int(round(o0 / BW)), int(round(o1 / BW))), divider=divider)


def _plan():
    """A hallway (space 0, 2 x 10 m, not refined) and a refined room (refinement 0) cut into a room (space 1,
    5 x 5 m) and the hallway's end (space 2, 2 x 3 m) that building-wide merging had glued to the room."""
    cells = [_cell(0, 2, 0, 10),  # hallway
             _cell(2, 7, 0, 5),  # room (refined piece)
             _cell(0, 2, 10, 13)]  # hallway end (refined piece)
    labels = np.array([0, 1, 2])
    edges = [_edge(0, 2, 1, 10, 0, 2),  # hallway | its end: open, 2 m
             _edge(0, 1, 0, 2, 0, 5, {"kind": "peak-gap-peak"})]  # hallway | room: a wall
    sides = np.array([[0, 2], [0, 1]])
    return cells, edges, labels, sides


def test_a_refined_piece_rejoins_its_space_through_an_open_face():
    cells, edges, labels, sides = _plan()
    group = rejoin_pieces(cells, edges, labels, sides, np.array([-1, 0, 0]), BW, MergeRules())
    assert group.tolist() == [0, 1, 0]


def test_faces_between_spaces_not_refined_are_not_decided_again():
    cells, edges, labels, sides = _plan()
    group = rejoin_pieces(cells, edges, labels, sides, np.array([-1, -1, -1]), BW, MergeRules())
    assert group.tolist() == [0, 1, 2]


def test_two_pieces_of_one_refinement_never_join():
    cells, edges, labels, sides = _plan()
    # the room and the hallway's end share an open face, and the end touches the hallway too
    edges = edges + [_edge(2, 1, 0, 2, 10, 13)]
    cells[1] = _cell(2, 7, 0, 13)
    sides = np.vstack([sides, [[2, 1]]])
    group = rejoin_pieces(cells, edges, labels, sides, np.array([-1, 0, 0]), BW, MergeRules())
    assert group[1] != group[2]
    # without the hallway beside it the end stays alone rather than going back to the room
    only = rejoin_pieces(cells, edges[2:], labels, sides[2:], np.array([-1, 0, 0]), BW, MergeRules())
    assert only.tolist() == [0, 1, 2]


def test_a_small_opening_or_an_unscanned_piece_does_not_join():
    cells, edges, labels, sides = _plan()
    # the open face is 0.1 m of a large piece's boundary: under min_open_ratio
    cells[2] = _cell(0, 2, 10, 40)
    edges[0] = _edge(0, 2, 1, 10, 0, 0.1)
    group = rejoin_pieces(cells, edges, labels, sides, np.array([-1, 0, 0]), BW, MergeRules())
    assert group.tolist() == [0, 1, 2]
    # a nearly unscanned piece: its faces are no evidence of an opening
    cells, edges, labels, sides = _plan()
    cells[2] = _cell(0, 2, 10, 13, count=1)
    group = rejoin_pieces(cells, edges, labels, sides, np.array([-1, 0, 0]), BW, MergeRules())
    assert group.tolist() == [0, 1, 2]


def test_a_face_tested_in_another_frame_counts_only_as_a_long_side():
    """A face tested in another frame than a side's joins only where it makes ``across_ratio`` of the smaller
    group's boundary: the hallway's end (2 x 3 m, boundary 10 m) shares 2 m with the hallway, 0.2 of it."""
    cells, edges, labels, sides = _plan()
    src, across = np.array([-1, 0, 0]), np.array([True, False])
    assert rejoin_pieces(cells, edges, labels, sides, src, BW, MergeRules(), across=across,
                         across_ratio=0.25).tolist() == [0, 1, 2]
    assert rejoin_pieces(cells, edges, labels, sides, src, BW, MergeRules(), across=across,
                         across_ratio=0.15).tolist() == [0, 1, 0]
    # the same face tested in its sides' frame joins at any across_ratio
    assert rejoin_pieces(cells, edges, labels, sides, src, BW, MergeRules(), across=np.array([False, False]),
                         across_ratio=1.0).tolist() == [0, 1, 0]
