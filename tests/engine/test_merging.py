"""Merging: the neighbour graph of cells, the divider test across a shared face, components and absorption."""
from __future__ import annotations

import numpy as np

from engine.dividers import DividerParams
from engine.merging import Edge, MergeRules, face_divider, merge, neighbour_edges
from engine.slicing import Box

BW = 0.02


def _cell(u0, u1, v0, v1, count=1000, floor=0):
    b = [int(round(x / BW)) for x in (u0, u1, v0, v1)]
    return Box(floor, b[0], b[1], b[2], b[3], final=True, count=count)


def test_neighbour_edges_need_a_shared_face_of_min_length():
    cells = [_cell(0, 4, 0, 5), _cell(4, 8, 0, 3), _cell(4, 8, 3, 5), _cell(0, 4, 5, 9),
             _cell(8, 10, 4.9, 9),  # touches cell 2 over 0.1 m only
             _cell(0, 4, 0, 5, floor=1)]  # another storey: never a neighbour
    edges = neighbour_edges(cells, int(round(0.3 / BW)))
    pairs = sorted((e.a, e.b, e.axis) for e in edges)
    assert pairs == [(0, 1, 0), (0, 2, 0), (0, 3, 1), (1, 2, 1)]
    e = next(e for e in edges if (e.a, e.b) == (0, 2))
    assert e.overlap == (int(round(3 / BW)), int(round(5 / BW))) and e.position == int(round(4 / BW))


def _face_hist(wall: bool, door_fill: float = 0.0, window: int = 100, seed: int = 0):
    """Histograms (all heights, upper band) across a face at bin ``window``: rooms on both sides."""
    rng = np.random.default_rng(seed)
    lam = np.full(2 * window, 60.0)
    up = np.full(2 * window, 20.0)
    if wall:
        gap = slice(window - 5, window + 5)
        lam[gap] = 60.0 * door_fill
        up[gap] = 0.0
        for face in (window - 6, window + 5):
            lam[face] += 3000.0
            up[face] += 600.0
    return rng.poisson(lam).astype(float), rng.poisson(up).astype(float)


def test_face_divider_finds_a_wall_with_a_door_across_the_face():
    h, up = _face_hist(True, door_fill=0.6)
    d = face_divider(h, (0, 200), 1000, 100, DividerParams(bin_width=BW), up)
    assert d is not None and d["kind"] == "peak-gap-peak"
    assert abs(d["position"] - 1000 * BW) <= 0.05


def test_face_divider_finds_none_in_an_open_room_and_none_off_the_face():
    h, up = _face_hist(False)
    assert face_divider(h, (0, 200), 1000, 100, DividerParams(bin_width=BW), up) is None
    # a wall 1 m from the face is not a divider *across this face*
    h2, up2 = _face_hist(True)
    h2, up2 = np.roll(h2, 50), np.roll(up2, 50)
    assert face_divider(h2, (0, 200), 1000, 100, DividerParams(bin_width=BW), up2) is None


def test_face_divider_separates_cells_with_nothing_between_them():
    h, up = _face_hist(False)
    h[60:140] = 0
    up[60:140] = 0
    d = face_divider(h, (0, 200), 1000, 100, DividerParams(bin_width=BW), up)
    assert d is not None and d["kind"] == "empty"


def _edge(a, b, axis, pos, o0, o1, divided):
    return Edge(a, b, 0, axis, int(round(pos / BW)), (int(round(o0 / BW)), int(round(o1 / BW))),
                {"kind": "peak-gap-peak"} if divided else None, True)


def test_components_of_edges_without_divider_are_spaces():
    # an L-shaped room cut in two (no divider between its cells), a room beside it behind a wall
    cells = [_cell(0, 4, 0, 3), _cell(0, 4, 3, 6), _cell(4, 8, 3, 6)]
    edges = [_edge(0, 1, 1, 3, 0, 4, False), _edge(1, 2, 0, 4, 3, 6, True)]
    comps = merge(cells, edges, BW, MergeRules())
    assert comps.labels.tolist() == [0, 0, 1]


def test_small_cells_are_absorbed_by_the_neighbour_with_the_longest_face():
    cells = [_cell(0, 4, 0, 4), _cell(4, 8, 0, 4),
             _cell(4, 4.3, 4, 7),  # a sliver (0.3 m wide): too narrow to be a space
             _cell(0, 4, 4, 7),
             _cell(0, 0.6, 7, 8.5)]  # 0.9 m²: too small, touches cell 3 only, across a divider
    edges = [_edge(0, 1, 0, 4, 0, 4, True),
             _edge(1, 2, 1, 4, 4, 4.3, True),  # short face
             _edge(3, 2, 0, 4, 4, 7, True),  # long face
             _edge(0, 3, 1, 4, 0, 4, True),
             _edge(3, 4, 1, 7, 0, 0.6, True)]
    comps = merge(cells, edges, BW, MergeRules())
    assert comps.labels[2] == comps.labels[3]  # the longest shared face wins
    assert comps.labels[4] == comps.labels[3]
    assert len(set(comps.labels.tolist())) == 3
    assert len(comps.absorbed) == 2 and not comps.dropped
    # with a face without divider to cell 1, the sliver joins cell 1 even though the face is short
    edges[1] = _edge(1, 2, 1, 4, 4, 4.3, False)
    assert merge(cells, edges, BW, MergeRules()).labels[2] == merge(cells, edges, BW, MergeRules()).labels[1]


def test_a_weak_cell_without_neighbours_is_noise():
    cells = [_cell(0, 5, 0, 5, count=50000), _cell(20, 20.4, 20, 20.4, count=30)]
    comps = merge(cells, [], BW, MergeRules())
    assert comps.labels.tolist() == [0, -1]
    assert len(comps.dropped) == 1
