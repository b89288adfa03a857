"""Ceiling dividers: a face between a part of a storey with a ceiling and a part without one (a stair shaft)."""
from __future__ import annotations

import numpy as np

from engine.spaces.ceilings import CeilingSettings, ceiling_dividers, ceiling_occupancy
from engine.spaces.merging import Edge
from engine.spaces.ridges import Occupancy
from tests.engine.handmade import BAND, BW, ZB
from tests.engine.handmade import box_points as _surface
from tests.engine.handmade import point_bins as _bins

P = CeilingSettings()


def _lobby_and_shaft(rng, per_m2: float = 250.0) -> np.ndarray:
    """A lobby (u 0-8 m, v 0-6 m, ceiling at 3.0 m) beside a stair shaft (u 8-12 m) whose ceiling lies in the next
    storey: in this storey the shaft shows its walls up to the storey's top (4.0 m) and a flight in its far half,
    no horizontal surface above its landing.  The wall between them at u 8 m is seen from both sides."""
    pts = [_surface(rng, int(per_m2 * 48), (0, 8), (0, 6), (0, 0)),        # floors
           _surface(rng, int(per_m2 * 24), (8, 12), (0, 6), (0, 0)),
           _surface(rng, int(per_m2 * 48), (0, 8), (0, 6), (3.0, 3.0)),    # the lobby's ceiling
           _surface(rng, int(per_m2 * 6 * 3.0), (7.98, 7.985), (0, 6), (0, 3.0)),   # the wall, lobby side
           _surface(rng, int(per_m2 * 6 * 4.0), (8.015, 8.02), (0, 6), (0, 4.0)),   # the wall, shaft side
           _surface(rng, int(per_m2 * 6 * 4.0), (11.995, 12.0), (0, 6), (0, 4.0)),  # the shaft's far wall
           _surface(rng, int(per_m2 * 4 * 1.4), (10.5, 12), (3, 6), (2.6, 2.6))]   # a landing of the flight
    return np.concatenate(pts)


def test_the_ceiling_raster_keeps_horizontal_surfaces_and_not_walls():
    rng = np.random.default_rng(0)
    bu, bv, bz = _bins(_lobby_and_shaft(rng))
    occ = ceiling_occupancy(bu, bv, bz, BAND, P, BW, ZB)
    depth = int(round(0.5 / BW))
    # the lobby side of the wall reads ceiling all along; the shaft side (its landing) reads none: the shaft's
    # wall runs down the upper band (it is in the plain upper-band raster, which cannot tell)
    below, above = occ.side_fraction(0, 800, 0, 600, depth)
    assert below > 0.9 and above == 0.0
    plain = Occupancy.build(bu, bv, bz, BAND, occ.pixel)
    assert min(plain.side_fraction(0, 800, 0, 600, depth)) > 0.9
    # a horizontal landing of the flight is a horizontal surface: it reads as ceiling where it is
    assert occ.side_fraction(0, 1100, 300, 600, depth)[1] > 0.9


def test_a_face_between_a_ceiling_and_no_ceiling_is_divided():
    rng = np.random.default_rng(1)
    bu, bv, bz = _bins(_lobby_and_shaft(rng))
    occ = ceiling_occupancy(bu, bv, bz, BAND, P, BW, ZB)
    shaft = Edge(0, 1, 0, 0, 800, (0, 600))
    room = Edge(2, 3, 0, 0, 400, (0, 600))  # inside the lobby: ceiling on both sides
    well = Edge(4, 5, 0, 0, 1000, (0, 300))  # inside the shaft: no ceiling on either side
    walled = Edge(0, 1, 0, 0, 800, (0, 600), divider={"kind": "peak-gap-peak"})
    got = ceiling_dividers([shaft, room, well, walled], occ, P, BW)
    assert got[0].divider is not None and got[0].divider["kind"] == "ceiling"
    assert got[1] is room and got[2] is well and got[3] is walled
    # span 0 switches it off
    off = ceiling_dividers([shaft], occ, CeilingSettings(span=0.0), BW)
    assert off[0].divider is None


def test_a_face_whose_two_sides_end_at_the_same_place_is_not_divided():
    # a face that runs beyond the building (cells stretched by flying points): along its first half both sides
    # have a ceiling, along the second neither.  Each side has a ceiling along half of it, but the ceiling does
    # not stop AT the face: no divider (a rule on the two sides' fractions alone would be on a knife edge here)
    img = np.zeros((100, 100), dtype=bool)
    img[:, :50] = True
    occ = Occupancy(img, 0, 0, 10)
    e = Edge(0, 1, 0, 0, 500, (0, 1000))
    assert occ.side_fraction(0, 500, 0, 1000, 50) == (0.5, 0.5)
    assert ceiling_dividers([e], occ, P, BW)[0].divider is None
    # the same face with the ceiling on one side only is divided
    img2 = img.copy()
    img2[50:, :] = False
    assert ceiling_dividers([e], Occupancy(img2, 0, 0, 10), P, BW)[0].divider["kind"] == "ceiling"


def test_occupancy_side_profiles_match_side_fraction():
    img = np.zeros((20, 10), dtype=bool)
    img[3, 2:6] = True   # below a face at u bin 50 (pixel 10 bins): within 30 bins
    img[7, 4:10] = True  # above it
    occ = Occupancy(img, 0, 0, 10)
    below, above = occ.side_profiles(0, 50, 0, 100, 30)
    assert below.tolist() == [False, False, True, True, True, True, False, False, False, False]
    assert above.tolist() == [False] * 4 + [True] * 6
    assert occ.side_fraction(0, 50, 0, 100, 30) == (0.4, 0.6)


def _two_ceilings(rng, low: float = 3.0, high: float = 3.4, per_m2: float = 250.0, glass: bool = True) -> np.ndarray:
    """Two rooms side by side (u 0-5 m and 5-10 m, v 0-6 m) under ceilings at ``low`` and ``high`` m, parted at
    u 5 m by a glass partition (sparse: 6 % of the density, no void, no ridge) and closed by exterior walls."""
    pts = [_surface(rng, int(per_m2 * 60), (0, 10), (0, 6), (0, 0)),
           _surface(rng, int(per_m2 * 30), (0, 5), (0, 6), (low, low)),
           _surface(rng, int(per_m2 * 30), (5, 10), (0, 6), (high, high))]
    for u, top in ((0.0, low), (9.995, high)):
        pts.append(_surface(rng, int(per_m2 * 6 * top), (u, u + 0.005), (0, 6), (0, top)))
    for v in (0.0, 5.995):
        pts.append(_surface(rng, int(per_m2 * 5 * low), (0, 5), (v, v + 0.005), (0, low)))
        pts.append(_surface(rng, int(per_m2 * 5 * high), (5, 10), (v, v + 0.005), (0, high)))
    if glass:
        pts.append(_surface(rng, int(0.06 * per_m2 * 6 * high * 2), (4.96, 5.04), (0, 6), (0, high)))
    pts.append(_surface(rng, int(per_m2 * 6 * (high - low)), (4.995, 5.0), (0, 6), (low, high)))  # the step's face
    return np.concatenate(pts)


def _steps(pts: np.ndarray, p: CeilingSettings = P):
    from engine.spaces.ceilings import step_lines
    from engine.spaces.ridges import RidgeSettings

    bu, bv, bz = _bins(pts)
    return step_lines(ceiling_occupancy(bu, bv, bz, BAND, p, BW, ZB), p, RidgeSettings(), BW, ZB,
                      points=(bu, bv, bz), floor_z=0)


def test_a_line_where_the_ceiling_changes_height_is_a_step_line():
    rng = np.random.default_rng(3)
    lines = _steps(_two_ceilings(rng))
    assert len(lines) == 1
    r = lines[0]
    assert r.axis == 0 and abs(r.cut * BW - 5.0) <= 0.1
    assert r.covered(0, 600) >= 500  # along (nearly) the whole 6 m
    # one ceiling height: no step line (noise and a 5 cm difference are not a step)
    assert _steps(_two_ceilings(rng, 3.0, 3.05)) == []
    # step 0: off
    assert _steps(_two_ceilings(rng), CeilingSettings(step=0.0)) == []


def test_a_beam_and_its_shadow_are_no_step():
    # a beam (0.3 m wide, 0.4 m deep) across a room under one ceiling at 3.0 m; the ceiling 0.4 m beyond the beam
    # on one side lies in its shadow (not scanned).  Beside the beam's edge one side shows the beam's underside
    # 0.4 m below the ceiling, but not over a whole window at one height: the beam with the ceiling beyond it
    rng = np.random.default_rng(4)
    pts = [_surface(rng, 250 * 60, (0, 10), (0, 6), (0, 0)),
           _surface(rng, 250 * 28, (0, 4.7), (0, 6), (3.0, 3.0)),
           _surface(rng, 250 * 29, (5.4, 10), (0, 6), (3.0, 3.0)),      # shadow: 5.0-5.4 m unscanned
           _surface(rng, 250 * 2, (4.7, 5.0), (0, 6), (2.6, 2.6)),      # the beam's underside
           _surface(rng, 250 * 3, (4.7, 4.705), (0, 6), (2.6, 3.0)),    # its sides
           _surface(rng, 250 * 3, (4.995, 5.0), (0, 6), (2.6, 3.0))]
    pts = np.concatenate(pts)
    assert _steps(pts) == []
    assert _steps(pts, CeilingSettings(level_window=0.5)) == []
    # the same beam 1.2 m wide (a lowered ceiling over a whole window) is a step, but a bulkhead with nothing
    # under its edges: no step line with the partition test
    wide = np.concatenate([pts, _surface(rng, 250 * 6, (3.8, 4.7), (0, 6), (2.6, 2.6))])
    wide = wide[~((wide[:, 0] >= 3.8) & (wide[:, 0] < 4.7) & (wide[:, 2] > 2.9))]
    assert _steps(wide, CeilingSettings(min_partition=0.0)) != []
    assert _steps(wide) == []


def _refined_spaces(pts: np.ndarray, ceilings: CeilingSettings) -> int:
    """Spaces of the refinement of one storey (floor at z 0, upper band from 2.2 m) parsed from ``pts``."""
    from engine.spaces.alignment import Frame
    from engine.spaces.histograms import Grid
    from engine.spaces.memory_store import MemoryStore
    from engine.spaces.part import parse_part
    from engine.spaces.settings import SpaceSettings

    raw = {a: np.round(pts[:, i] / 0.001).astype(np.int64) for i, a in enumerate("xyz")}
    mem = MemoryStore(raw, (0.001,) * 3, (0.0,) * 3, (0.0, 0.0, 0.0))
    p = SpaceSettings(ceilings=ceilings)
    grid = Grid.for_store(mem, Frame(0.0, (0.0, 0.0, 0.0)), p.bin_width, p.z_bin)
    return parse_part(mem, 0.0, grid, p, 0, np.array([[-1, int(4.0 / ZB)]]), np.array([BAND])).n_spaces


def test_rooms_under_two_ceilings_parted_by_glass_are_two_spaces_in_the_refinement():
    pts = _two_ceilings(np.random.default_rng(5))
    spaces = [_refined_spaces(pts, CeilingSettings(step=step)) for step in (0.1, 0.0)]
    # the glass leaves no void and no ridge: without the step line the two rooms are one space
    assert spaces == [2, 1]


def _soffit_room(rng, per_m2: float = 250.0, furniture: bool = True) -> np.ndarray:
    """One room (u 0-8 m, v 0-6 m) under a ceiling at 3.0 m, with a soffit along its whole wall at u 0: a strip
    1.5 m wide whose ceiling is 0.4 m lower (2.6 m), closed by its vertical face at u 1.5 m from 2.6 to 3.0 m.
    Under the soffit's edge there is open air down to the floor; with ``furniture``, a desk (top at 0.75 m)
    crosses the edge at v 2.0-2.8 m and a cabinet (1.2 m tall) stands astride it at v 4.55-5.0 m."""
    pts = [_surface(rng, int(per_m2 * 48), (0, 8), (0, 6), (0, 0)),
           _surface(rng, int(per_m2 * 9), (0, 1.5), (0, 6), (2.6, 2.6)),             # the soffit's underside
           _surface(rng, int(per_m2 * 39), (1.5, 8), (0, 6), (3.0, 3.0)),            # the room's ceiling
           _surface(rng, int(per_m2 * 6 * 0.4), (1.5, 1.505), (0, 6), (2.6, 3.0))]   # the soffit's face
    for u, top in ((0.0, 2.6), (7.995, 3.0)):
        pts.append(_surface(rng, int(per_m2 * 6 * top), (u, u + 0.005), (0, 6), (0, top)))
    for v in (0.0, 5.995):
        pts.append(_surface(rng, int(per_m2 * 1.5 * 2.6), (0, 1.5), (v, v + 0.005), (0, 2.6)))
        pts.append(_surface(rng, int(per_m2 * 6.5 * 3.0), (1.5, 8), (v, v + 0.005), (0, 3.0)))
    if furniture:
        pts.append(_surface(rng, int(per_m2 * 1.6 * 0.8), (1.1, 2.7), (2.0, 2.8), (0.75, 0.75)))
        pts.append(_surface(rng, int(per_m2 * 0.6 * 0.45), (1.2, 1.8), (4.55, 5.0), (1.2, 1.2)))
        pts.append(_surface(rng, int(per_m2 * 0.6 * 1.2), (1.2, 1.8), (4.55, 4.555), (0, 1.2)))
    return np.concatenate(pts)


def test_a_soffit_edge_is_no_step_line():
    # the ceiling changes height by 0.4 m along the whole 6 m edge, each side level over more than 1 m: the
    # step alone cannot tell it from a partition.  Under the edge there is no partition, only the floor, the walls
    # at its ends and two pieces of furniture: no step line
    rng = np.random.default_rng(6)
    for furniture in (False, True):
        pts = _soffit_room(rng, furniture=furniture)
        assert _steps(pts) == []
        # without the partition test (the first rule) it is one
        off = _steps(pts, CeilingSettings(min_partition=0.0))
        assert len(off) == 1 and abs(off[0].cut * BW - 1.5) <= 0.15
    # a row of desks across the edge along most of it: points near the line in most stretches, but in the lower
    # half of the band only (a partition stands at all heights): no step line; one band alone takes it for one
    desks = [_surface(rng, 200, (1.1, 2.7), (v, v + 0.8), (0.75, 0.75)) for v in (0.6, 1.6, 2.6, 3.6, 4.6)]
    row = np.concatenate([_soffit_room(rng, furniture=False)] + desks)
    assert _steps(row) == []
    assert len(_steps(row, CeilingSettings(both_halves=False))) == 1


def test_a_step_over_a_partition_with_an_open_door_is_a_step_line():
    # the glazed partition of _two_ceilings with a 1 m doorway (open: nothing under its head at 2.1 m) and a
    # mullion every 1.2 m: the stretches of the doorway still hold the glass above its head
    rng = np.random.default_rng(7)
    pts = _two_ceilings(rng)
    door = (np.abs(pts[:, 0] - 5.0) < 0.1) & (pts[:, 1] > 2.5) & (pts[:, 1] < 3.5) & (pts[:, 2] > 0.02) \
        & (pts[:, 2] < 2.1)
    pts = np.concatenate([pts[~door]] + [_surface(rng, 120, (4.97, 5.03), (v, v + 0.05), (0, 3.4))
                                         for v in (1.2, 2.4, 3.6, 4.8)])
    lines = _steps(pts)
    assert len(lines) == 1 and lines[0].covered(0, 600) >= 500


def test_partition_support_counts_the_stretches_with_a_point_near_the_line():
    from engine.spaces.ceilings import partition_support

    # a line along v at u bin 100 (200 at the fourth stretch: a line drifting), stretches of 50 bins from v 0
    centre = np.array([100.0, 100.0, 100.0, 200.0])
    normal = np.array([95, 130, 109, 100, 195])   # within 10 bins: stretch 0 (95), 2 (109), 3 (195)
    along = np.array([10, 60, 120, 160, 199])
    got = partition_support(normal, along, 0, 50, centre, 10)
    assert got.tolist() == [True, False, True, True]
    # points beyond the stretches are ignored
    assert partition_support(np.array([100]), np.array([-5]), 0, 50, centre, 10).tolist() == [False] * 4


def test_step_lines_need_the_points_for_the_partition_test():
    import pytest

    from engine.spaces.ceilings import step_lines
    from engine.spaces.ridges import RidgeSettings

    bu, bv, bz = _bins(_two_ceilings(np.random.default_rng(8)))
    occ = ceiling_occupancy(bu, bv, bz, BAND, P, BW, ZB)
    with pytest.raises(ValueError):
        step_lines(occ, P, RidgeSettings(), BW, ZB)
    assert len(step_lines(occ, CeilingSettings(min_partition=0.0), RidgeSettings(), BW, ZB)) == 1


def test_a_room_with_a_soffit_stays_one_space_in_the_refinement():
    pts = _soffit_room(np.random.default_rng(9))
    # the first rule cut the room at the soffit's edge; with the partition test it is one space
    assert [_refined_spaces(pts, CeilingSettings(min_partition=m)) for m in (P.min_partition, 0.0)] == [1, 2]


def test_ceiling_params_from_the_settings():
    p = CeilingSettings.from_dict({"both-halves": False, "min-partition": "0.25", "floor-band": 0.3, "other": 1})
    assert p.both_halves is False and p.min_partition == 0.25 and p.floor_band == 0.3
    assert CeilingSettings.from_dict(CeilingSettings().to_dict()) == CeilingSettings()


def test_a_ridge_along_part_of_a_step_line_leaves_the_rest_of_it():
    """A wall seen as a ridge along part of its length and as a ceiling step along the rest (a hallway's glazed
    side): the step line keeps the stretch the ridge does not cover, where it is long enough (it was dropped
    whole before)."""
    from engine.spaces.ceilings import step_lines
    from engine.spaces.ridges import RidgeLine, RidgeSettings

    rng = np.random.default_rng(3)
    bu, bv, bz = _bins(_two_ceilings(rng))
    occ = ceiling_occupancy(bu, bv, bz, BAND, P, BW, ZB)
    cut, m = int(round(5.0 / BW)), int(round(1.0 / BW))

    def steps(ridge_runs):
        return step_lines(occ, P, RidgeSettings(), BW, ZB, [RidgeLine(0, cut, ridge_runs, 1.0)],
                          points=(bu, bv, bz), floor_z=0)

    lines = steps(((0, 2 * m),))  # a ridge over v 0-2 m of the 6 m step
    assert len(lines) == 1
    assert lines[0].covered(0, 2 * m) == 0 and lines[0].covered(2 * m, 6 * m) >= int(3.5 * m)
    assert steps(((0, 4 * m),)) == []  # the rest (2 m) is shorter than a ridge line's min-run (3 m)
    assert steps(((0, 6 * m),)) == []


def test_uncovered_runs():
    from engine.spaces.ceilings import uncovered_runs
    from engine.spaces.ridges import RidgeLine

    lines = [RidgeLine(0, 0, ((200, 400), (380, 500)), 1.0), RidgeLine(0, 3, ((900, 950),), 1.0)]
    assert uncovered_runs([(0, 1000)], lines, 100) == ((0, 200), (500, 900))
    assert uncovered_runs([(0, 1000)], lines, 300) == ((500, 900),)
    assert uncovered_runs([(0, 150), (600, 800)], lines, 10) == ((0, 150), (600, 800))
