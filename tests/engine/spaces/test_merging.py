"""Merging: the neighbour graph of cells, the divider test across a shared face, components and absorption."""
from __future__ import annotations

import numpy as np

from engine.spaces.dividers import DividerSettings
from engine.spaces.merging import Edge, MergeRules, face_divider, merge, neighbour_edges
from engine.spaces.slicing import Box

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
    d = face_divider(h, (0, 200), 1000, 100, DividerSettings(bin_width=BW), up)
    assert d is not None and d["kind"] == "peak-gap-peak"
    assert abs(d["position"] - 1000 * BW) <= 0.05


def test_face_divider_finds_none_in_an_open_room_and_none_off_the_face():
    h, up = _face_hist(False)
    assert face_divider(h, (0, 200), 1000, 100, DividerSettings(bin_width=BW), up) is None
    # a wall 1 m from the face is not a divider *across this face*
    h2, up2 = _face_hist(True)
    h2, up2 = np.roll(h2, 50), np.roll(up2, 50)
    assert face_divider(h2, (0, 200), 1000, 100, DividerSettings(bin_width=BW), up2) is None


def test_face_divider_separates_cells_with_nothing_between_them():
    h, up = _face_hist(False)
    h[60:140] = 0
    up[60:140] = 0
    d = face_divider(h, (0, 200), 1000, 100, DividerSettings(bin_width=BW), up)
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


def _two_rooms_one_leak():
    """Room A (10 x 6 m, one cell) beside room B (cells 1: 9 x 6 m, 2: 1 x 6 m) behind a 10 m wall whose
    divider was found along 9 m and missed along the last 1 m (a leaky face)."""
    cells = [_cell(0, 10, 0, 6), _cell(0, 9, 6, 12), _cell(9, 10, 6, 12)]
    edges = [_edge(0, 1, 1, 6, 0, 9, True),
             _edge(0, 2, 1, 6, 9, 10, False),  # the leak: 1 m of a 32 m boundary
             _edge(1, 2, 0, 9, 6, 12, False)]  # inside room B: 6 m
    return cells, edges


def test_one_leaky_face_does_not_chain_two_rooms():
    cells, edges = _two_rooms_one_leak()
    comps = merge(cells, edges, BW, MergeRules())
    assert comps.labels.tolist() == [0, 1, 1]  # connected components would give [0, 0, 0]
    assert comps.refused == [(0, 1)] and not comps.absorbed
    # the same face as an opening of a room cut in two: a third of the smaller group's boundary joins
    cells2 = [_cell(0, 10, 0, 6), _cell(0, 9, 6, 12), _cell(9, 10, 6, 12)]
    edges2 = [_edge(0, 1, 1, 6, 0, 9, False), edges[1], edges[2]]
    assert merge(cells2, edges2, BW, MergeRules()).labels.tolist() == [0, 0, 0]


def test_a_chain_of_leaks_through_a_hallway_stays_apart():
    # four 5 x 5 m rooms along a 2 m hallway; each wall to the hallway has its divider along 4.4 m and a
    # leaky 0.6 m piece (3 % of the room's 20 m boundary); the rooms are apart from each other
    cells = [_cell(5 * i, 5 * i + 5, 0, 5) for i in range(4)] + [_cell(0, 20, 5, 7)]
    edges = [_edge(i, 4, 1, 5, 5 * i, 5 * i + 4.4, True) for i in range(4)]
    edges += [_edge(i, 4, 1, 5, 5 * i + 4.4, 5 * i + 5, False) for i in range(4)]
    edges += [_edge(i, i + 1, 0, 5 * i + 5, 0, 5, True) for i in range(3)]
    comps = merge(cells, edges, BW, MergeRules())
    assert comps.labels.tolist() == [0, 1, 2, 3, 4]  # connected components: one space
    assert len(comps.refused) == 4


def test_a_nearly_unscanned_cell_does_not_bridge_two_rooms():
    # two rooms whose only link is a sparse cell between them (an unscanned strip with flying points)
    cells = [_cell(0, 5, 0, 5, count=50000), _cell(5, 6, 0, 5, count=40), _cell(6, 11, 0, 5, count=50000)]
    edges = [_edge(0, 1, 0, 5, 0, 5, False), _edge(1, 2, 0, 6, 0, 5, False)]
    rules = MergeRules(min_relative_density=0.0)  # keep the strip a space of its own: no absorption
    assert merge(cells, edges, BW, rules).labels.tolist() == [0, 1, 2]
    # absorbed as a weak group, it joins ONE of them
    labels = merge(cells, edges, BW, MergeRules()).labels.tolist()
    assert labels[0] != labels[2] and labels[1] in (labels[0], labels[2])


def test_face_divider_empty_run_tolerates_stray_points():
    h, up = _face_hist(False)
    h[60:140] = 0
    up[60:140] = 0
    h[[70, 95, 101, 130]] = 1  # flying points in the unscanned stretch
    d = face_divider(h, (0, 200), 1000, 100, DividerSettings(bin_width=BW), up)
    assert d is not None and d["kind"] == "empty"
    # a real floor (room level everywhere) is not nearly empty
    h2, up2 = _face_hist(False)
    assert face_divider(h2, (0, 200), 1000, 100, DividerSettings(bin_width=BW), up2) is None


def test_without_a_scanned_floor_only_a_void_in_the_upper_band_and_below_it_divides():
    import dataclasses

    p = DividerSettings()
    window = 160
    n = 2 * window
    gap = slice(window - 10, window + 10)  # a 20 cm void at the face
    faces = [slice(window - 14, window - 10), slice(window + 10, window + 14)]

    def hist(level: float, face: float, void: bool) -> np.ndarray:
        h = np.full(n, level)
        for f in faces:
            h[f] += face
        if void:
            h[gap] = 0.0
        return h

    furniture = hist(5.0, 60.0, True)  # two pieces of furniture, nothing in the upper band
    empty_band = np.zeros(n)
    beams = hist(2.0, 30.0, True)  # a gap between beams in the upper band, furniture-free below
    wall_band = hist(2.0, 30.0, True)
    only = dataclasses.replace(p, band_only=True)
    assert face_divider(furniture + empty_band, (0, n), window, window, p, empty_band) is not None
    assert face_divider(furniture + empty_band, (0, n), window, window, only, empty_band) is None
    below = np.full(n, 5.0)  # nothing divides below the beams
    assert face_divider(below + beams, (0, n), window, window, only, beams) is None
    wall_below = hist(5.0, 60.0, True)  # a wall: its faces and void run from the floor to the ceiling
    assert face_divider(wall_below + wall_band, (0, n), window, window, only, wall_band) is not None
