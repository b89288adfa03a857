"""Ridge dividers: a wall seen as one dense surface is found; columns, beams, partitions and exterior walls are not."""
from __future__ import annotations

import numpy as np

from engine.spaces.dividers import DividerSettings, detect_dividers
from engine.spaces.merging import Edge, ridge_faces
from engine.spaces.ridges import (
    Occupancy,
    RidgeLine,
    RidgeSettings,
    box_cuts,
    face_pieces,
    find_ridges,
    local_level,
    space_ridges,
)
from engine.spaces.slicing import split_histogram
from tests.engine.handmade import BAND, BW, ZB
from tests.engine.handmade import box_points as _surface
from tests.engine.handmade import point_bins as _bins

P = RidgeSettings()


def _rooms(rng, width: float = 10.0, depth: float = 6.0, height: float = 3.0, per_m2: float = 250.0) -> np.ndarray:
    """Floor and ceiling of a 10 x 6 m stretch and its exterior walls (each seen from inside only)."""
    area = width * depth
    pts = [_surface(rng, int(per_m2 * area), (0, width), (0, depth), (0.0, 0.0)),
           _surface(rng, int(per_m2 * area), (0, width), (0, depth), (height, height))]
    for u in (0.0, width):
        pts.append(_surface(rng, int(per_m2 * depth * height), (u, u + 0.005), (0, depth), (0, height)))
    for v in (0.0, depth):
        pts.append(_surface(rng, int(per_m2 * width * height), (0, width), (v, v + 0.005), (0, height)))
    return np.concatenate(pts)


def _merged_wall(rng, u: float = 5.0, depth: float = 6.0, height: float = 3.0, per_m2: float = 250.0,
                 shift: float = 0.02) -> np.ndarray:
    """A thin wall between two rooms whose two faces were registered ``shift`` m apart the wrong way: one ridge."""
    n = int(per_m2 * depth * height)
    a = _surface(rng, n, (u, u + 0.01), (0, depth), (0, height))
    b = _surface(rng, n, (u + shift, u + shift + 0.01), (0, depth), (0, height))
    return np.concatenate([a, b])


def _ridges(pts: np.ndarray) -> list[RidgeLine]:
    bu, bv, bz = _bins(pts)
    return space_ridges(bu, bv, bz, BAND, ZB, P, BW)


def _at_u(ridges: list[RidgeLine], u: float, tol: float = 0.1) -> list[RidgeLine]:
    return [r for r in ridges if r.axis == 0 and abs(r.cut * BW - u) <= tol]


def test_a_wall_seen_as_one_surface_is_a_ridge_line_but_no_void_divider():
    rng = np.random.default_rng(0)
    pts = np.concatenate([_rooms(rng), _merged_wall(rng)])
    bu, bv, bz = _bins(pts)
    # peak-gap-peak finds nothing at the wall: there is no void (this is why ridges exist)
    up = bz >= BAND
    h = np.bincount(bu - bu.min())
    hu = np.bincount(bu[up] - bu.min(), minlength=len(h))
    found = detect_dividers(h, DividerSettings(), start=bu.min() * BW, upper=hu)
    assert not [d for d in found if abs(d.position - 5.0) < 0.3]
    got = _at_u(space_ridges(bu, bv, bz, BAND, ZB, P, BW), 5.0)
    assert len(got) == 1
    assert got[0].covered(0, int(6.0 / BW)) >= 0.9 * 6.0 / BW  # it runs along the whole wall


def test_no_ridge_for_a_row_of_columns_a_beam_a_partition_or_tall_furniture():
    rng = np.random.default_rng(1)
    room = _rooms(rng)
    clutter = []
    for v0 in np.arange(0.5, 6.0, 2.0):  # a row of 0.4 m columns every 2 m, floor to ceiling, along u = 5
        for u in (5.0, 5.4):
            clutter.append(_surface(rng, 300, (u, u + 0.01), (v0, v0 + 0.4), (0, 3.0)))
    # a beam along u = 3 under the ceiling, its bottom 0.35 m below it: faces and bottom
    for u in (3.0, 3.3):
        clutter.append(_surface(rng, 600, (u, u + 0.01), (0, 6.0), (2.65, 3.0)))
    clutter.append(_surface(rng, 500, (3.0, 3.3), (0, 6.0), (2.65, 2.65)))
    # a cubicle spine along u = 7 (1.5 m high) and a row of tall bookcases along u = 8.5 (2.1 m)
    clutter.append(_surface(rng, 3000, (7.0, 7.01), (0.5, 5.5), (0, 1.5)))
    clutter.append(_surface(rng, 4000, (8.5, 8.52), (0.3, 5.7), (0, 2.1)))
    ridges = _ridges(np.concatenate([room] + clutter))
    assert not [r for r in ridges if r.axis == 0 and 1.0 < r.cut * BW < 9.0]
    # the same with a real wall at u = 5 instead of the columns: found
    ridges = _ridges(np.concatenate([room, _merged_wall(rng)] + clutter[6:]))
    assert len(_at_u(ridges, 5.0)) == 1


def test_an_exterior_wall_or_a_short_wall_is_no_ridge_line():
    rng = np.random.default_rng(2)
    room = _rooms(rng)
    ridges = _ridges(room)
    assert not [r for r in ridges if r.axis == 0]  # u = 0 and u = 10: nothing scanned beyond them
    # a wall seen from one side only: beyond it (u < 5) the floor was scanned through the door, not the ceiling
    seen = room[~((room[:, 0] < 5.0) & (room[:, 2] > 2.5))]
    one_face = _surface(rng, int(250 * 6.0 * 3.0), (5.0, 5.01), (0, 6.0), (0, 3.0))
    assert not _at_u(_ridges(np.concatenate([seen, one_face])), 5.0)
    # a wall stub of 2 m (a pier, a portal across a hallway): shorter than min_run
    stub = _merged_wall(rng, depth=2.0)
    assert not _at_u(_ridges(np.concatenate([room, stub])), 5.0)


def test_a_ridge_line_turned_by_a_fraction_of_a_degree_is_still_one_line():
    rng = np.random.default_rng(3)
    wall = _merged_wall(rng)
    wall[:, 0] += 0.02 * wall[:, 1]  # 1.15 degrees: 12 cm over the 6 m wall (drift from chunk to chunk)
    got = _at_u(_ridges(np.concatenate([_rooms(rng), wall])), 5.06)
    assert len(got) == 1 and got[0].length * BW >= 4.0


def test_find_ridges_needs_the_low_slice():
    # the same dense line of points, but only above the low slice (a beam's face): no ridge
    rng = np.random.default_rng(4)
    n = 20000
    ceiling = np.stack([rng.integers(0, 1000, n), rng.integers(0, 600, n)], axis=1)
    face = np.stack([rng.integers(500, 502, 4000), rng.integers(0, 600, 4000)], axis=1)
    normal = np.concatenate([ceiling[:, 0], face[:, 0]])
    along = np.concatenate([ceiling[:, 1], face[:, 1]])
    low_none = np.zeros(len(normal), bool)
    assert find_ridges(normal, along, low_none, 0, P, BW) == []
    low_face = np.r_[np.zeros(n, bool), np.ones(4000, bool)]
    got = find_ridges(normal, along, low_face, 0, P, BW)
    assert len(got) == 1 and abs(got[0].cut - 501) <= 3


def test_box_cuts_needs_the_run_inside_the_box_and_gives_way_to_voids():
    r = RidgeLine(0, 500, ((0, 400),), 8.0)
    assert box_cuts([r], 0, 0, 1000, (0, 600), P, BW) == [r]
    assert box_cuts([r], 0, 0, 1000, (250, 600), P, BW) == []  # only 1.5 m of it inside the box
    assert box_cuts([r], 1, 0, 1000, (0, 600), P, BW) == []  # the other axis
    assert box_cuts([r], 0, 480, 1000, (0, 600), P, BW) == []  # at the box's edge
    assert box_cuts([r], 0, 0, 1000, (0, 600), P, BW, avoid=[530]) == []  # a void divider nearby


def test_split_histogram_cuts_at_a_ridge_unless_a_void_divider_is_near():
    h = np.full(1000, 5)
    sp = split_histogram(h, 0, DividerSettings(), None, ridges=[400])
    assert [p[:2] for p in sp.pieces] == [(0, 400), (400, 1000)]
    assert sp.dividers[0]["kind"] == "ridge"
    # a wall with a void at 600: its divider wins over a ridge 20 cm away
    h[560:580] = 200
    h[580:620] = 0
    h[620:640] = 200
    sp = split_histogram(h, 0, DividerSettings(), None, ridges=[580])
    assert [d["kind"] for d in sp.dividers] == ["peak-gap-peak"]


def test_face_pieces_divide_only_what_the_ridge_covers_where_scanned():
    r = RidgeLine(0, 500, ((0, 400),), 8.0)
    # a spur wall: 4 m of a 7 m face covered, the 3 m beyond its end stay open
    assert face_pieces([r], 0, 500, (0, 700), P, BW) == [(0, 400, r), (400, 700, None)]
    # a 0.6 m stretch left at the end of a run is no opening
    assert face_pieces([r], 0, 500, (0, 460), P, BW) == [(0, 460, r)]
    # too far from the face: untouched
    assert face_pieces([r], 0, 520, (0, 700), P, BW) == [(0, 700, None)]
    # the stretch beyond the spur not scanned on one side (outside the building): left out of the face
    bu, bv = np.meshgrid(np.arange(0, 1000, 5), np.arange(0, 700, 5), indexing="ij")
    bu, bv = bu.ravel(), bv.ravel()
    keep = ~((bu >= 500) & (bv >= 400))
    occ = Occupancy.build(bu[keep], bv[keep], np.full(keep.sum(), BAND), BAND, 10)
    assert face_pieces([r], 0, 500, (0, 700), P, BW, occ) == [(0, 400, r)]
    occ_all = Occupancy.build(bu, bv, np.full(len(bu), BAND), BAND, 10)
    assert face_pieces([r], 0, 500, (0, 700), P, BW, occ_all) == [(0, 400, r), (400, 700, None)]


def test_ridge_faces_splits_open_edges_only():
    r = RidgeLine(1, 300, ((100, 500),), 8.0)
    e_open = Edge(0, 1, 0, 1, 300, (0, 700))
    e_void = Edge(2, 3, 0, 1, 300, (0, 700), divider={"kind": "peak-gap-peak"})
    got = ridge_faces([e_open, e_void], [r], P, BW)
    assert [(e.overlap, None if e.divider is None else e.divider["kind"]) for e in got] == [
        ((0, 100), None), ((100, 500), "ridge"), ((500, 700), None), ((0, 700), "peak-gap-peak")]
    assert ridge_faces([e_open], [], P, BW) == [e_open]


def test_a_wall_between_a_dense_room_and_a_sparse_one_is_a_ridge_line():
    # each room scanned from its own stations: a wide room at 1000 points per m2 and a narrow one beside it at
    # 250 (both faces of the wall at their room's density).  The whole chunk's level is the wide room's
    # ceiling, against which the narrow room's side looked unscanned; the level beside the wall lies between.
    rng = np.random.default_rng(5)
    wide = _rooms(rng, width=12.0, per_m2=1000.0)
    narrow = _rooms(rng, width=4.0, per_m2=250.0)
    narrow = narrow[narrow[:, 0] > 0.01]  # its wall at u = 0 is the wide room's
    narrow[:, 0] += 12.0
    n = int(6.0 * 3.0)
    wall = np.concatenate([_surface(rng, 1000 * n, (11.99, 12.0), (0, 6.0), (0, 3.0)),
                           _surface(rng, 250 * n, (12.015, 12.025), (0, 6.0), (0, 3.0))])
    got = _at_u(_ridges(np.concatenate([wide, narrow, wall])), 12.0)
    assert len(got) == 1 and got[0].covered(0, int(6.0 / BW)) >= 0.9 * 6.0 / BW
    # the level beside a position lies between the two rooms' ceilings
    bu, bv, bz = _bins(np.concatenate([wide, narrow]))
    up = bz >= BAND
    h = np.bincount(bu[up] - bu[up].min())[:, None].astype(float)
    at = int(round(12.0 / BW)) - bu[up].min()
    level = local_level(h, 10, 5)[at, 0]
    dense, sparse = np.median(h[at - 60:at - 10]), np.median(h[at + 10:at + 60])
    assert sparse < level < dense


def test_local_level_leaves_out_the_wall_and_empty_groups():
    h = np.zeros((200, 1))
    h[:100] = 4.0  # a room ...
    h[100:110] = 50.0  # ... its wall ...
    # ... and nothing beyond (an exterior wall): the level beside the wall is the room's, not the wall's
    got = local_level(h, 10, 5)
    assert got[105, 0] == 4.0
    assert got[150, 0] == 50.0  # 4 m beyond: the wall's group is the only one occupied near
    assert local_level(np.zeros((200, 1)), 10, 5).max() == 0.0
