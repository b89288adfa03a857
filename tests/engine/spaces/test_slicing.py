"""Slicing: histograms cut at dividers and empty runs, storeys from z, recursive slicing of a hand-made storey."""
from __future__ import annotations

import numpy as np
import pytest

from engine.spaces.dividers import DividerSettings, vertical_params
from engine.spaces.slicing import find_storeys, floor_levels, split_histogram

BW = 0.02


def _z_hist(storeys, *, ceiling_extra=None, slab=0.3, height=2.8, area=200.0, density=300.0, seed=0):
    """z histogram of stacked storeys: floor and ceiling peaks, walls in between, slab voids.

    ``ceiling_extra``: (storey, extra height, area fraction, wall fraction) for rooms with a higher ceiling.
    """
    z = (np.arange(int((storeys * (height + slab) + 1.0) / BW)) + 0.5) * BW
    lam = np.zeros(len(z))
    for s in range(storeys):
        z0 = s * (height + slab)
        walls = (z >= z0) & (z < z0 + height)
        lam[walls] += density * 60.0 * BW  # 60 m of wall faces
        lam[int(z0 / BW)] += density * area
        lam[int((z0 + height) / BW) - 1] += density * area
        if ceiling_extra and ceiling_extra[0] == s:
            extra, frac, wall_frac = ceiling_extra[1:]
            lam[int((z0 + height) / BW) - 1] -= density * area * frac
            tall = (z >= z0 + height) & (z < z0 + height + extra)
            lam[tall] += density * 60.0 * BW * wall_frac
            lam[int((z0 + height + extra) / BW)] += density * area * frac
    return np.random.default_rng(seed).poisson(lam).astype(float)


def test_split_histogram_cuts_at_dividers_and_drops_empty_runs():
    # room | wall | room, then 1 m of nothing, then a small room
    n = 700
    h = np.full(n, 60.0)
    h[240:250] = 0.0
    h[239] = h[250] = 5000.0
    h[500:550] = 0.0
    h[:20] = 0.0  # empty margin shorter than empty_run: kept
    sp = split_histogram(h, 100, DividerSettings(bin_width=BW))
    starts = [p[0] for p in sp.pieces]
    assert len(sp.pieces) == 3
    assert starts[0] == 100 and abs(starts[1] - 345) <= 1 and starts[2] == 650
    assert sp.pieces[1][1] == 600 and sp.empties == [(600, 650)]
    assert sum(p[2] for p in sp.pieces) == h.sum()
    assert len(sp.dividers) == 1 and abs(sp.dividers[0]["cut"] - 345) <= 1


def test_without_a_scanned_floor_an_empty_run_inside_divides_nothing():
    # a room whose floor and ceiling were cropped: furniture along two walls, nothing in its 2 m middle
    h = np.full(600, 40.0)
    h[200:400] = 0.0
    h[:120] = 0.0  # and the empty ends beyond its walls still trim the box
    h[480:] = 0.0
    assert [p[:2] for p in split_histogram(h, 0, DividerSettings(bin_width=BW)).pieces] == [(120, 200), (400, 480)]
    sp = split_histogram(h, 0, DividerSettings(bin_width=BW), inner_empties=False)
    assert [p[:2] for p in sp.pieces] == [(120, 480)] and sp.empties == []


def test_two_storeys_are_found_with_the_slab_between():
    h = _z_hist(2)
    floors, divs = find_storeys(h, 0, vertical_params())
    assert len(floors) == 2
    assert len([d for d in divs if d.kind == "peak-gap-peak"]) == 1
    slab = divs[0].position
    assert 2.8 <= slab <= 3.1
    levels = floor_levels(h, 0, floors, BW)
    assert [round(lv * BW, 1) for lv in levels] == [0.0, 3.1]


def test_a_room_with_a_higher_ceiling_is_not_a_storey():
    # rooms with their ceiling at 2.8 m; a hall whose ceiling is 0.6 m higher, with a dense layer of
    # ducts and lights 0.3 m below it.  Between the ordinary ceilings and the ducts only the hall's
    # few walls: that looks like a slab, but the piece above it is no storey (thinner than 2 m)
    rng = np.random.default_rng(0)
    n = int(3.5 / BW)
    lam = np.zeros(n)
    lam[: int(2.8 / BW)] = 200.0  # walls
    lam[0] = lam[int(2.8 / BW) - 1] = 40000.0  # floor, ordinary ceilings
    lam[int(2.8 / BW):int(3.1 / BW)] = 20.0  # the hall's walls only
    lam[int(3.1 / BW):int(3.4 / BW)] = 400.0  # ducts and lights
    lam[int(3.4 / BW)] = 20000.0  # the hall's ceiling
    h = rng.poisson(lam).astype(float)
    unconstrained, _ = find_storeys(h, 0, vertical_params(), min_height=0.1)
    assert len(unconstrained) == 2  # the false cut exists without the rule
    floors, divs = find_storeys(h, 0, vertical_params(), min_height=2.0)
    assert floors == [(0, n)]
    assert [d for d in divs if d.kind == "peak-gap-peak"] == []
    # a real second storey above is kept: its piece is tall enough
    h2 = np.r_[h, np.zeros(int(0.4 / BW)), h]
    floors2, divs2 = find_storeys(h2, 0, vertical_params(), min_height=2.0)
    assert len(floors2) == 2 and 3.4 < divs2[0].position < 3.95


@pytest.mark.parametrize("lo", [0, -250, 1234])
def test_split_positions_follow_the_histogram_origin(lo):
    h = np.full(400, 50.0)
    h[200:210] = 0
    h[199] = h[210] = 4000.0
    sp = split_histogram(h, lo, DividerSettings(bin_width=BW))
    assert len(sp.dividers) == 1
    assert sp.dividers[0]["position"] == pytest.approx((lo + 205) * BW, abs=BW)
    assert [p[:2] for p in sp.pieces] == [(lo, lo + sp.dividers[0]["cut"] - lo), (sp.dividers[0]["cut"], lo + 400)]


def test_a_storey_whose_densest_low_surface_has_a_fifth_of_its_points_below_has_no_scanned_floor():
    from engine.spaces.slicing import floor_levels, floor_scanned

    z_bin = 0.02
    walls = np.full(150, 10.0)  # 0 ... 3 m of wall points
    with_floor = walls.copy()
    with_floor[0] += 2000.0  # the floor, the lowest surface
    with_floor[37] += 800.0  # table tops at 0.74 m
    cropped = walls.copy()
    cropped[37] += 800.0  # the floor was cropped away: the densest low bin is the tables
    hist = np.concatenate([with_floor, np.zeros(60), cropped])
    floors = [(0, 150), (210, 360)]
    ground = floor_levels(hist, 0, floors, z_bin)
    assert ground == [0, 247]
    levels, scanned = floor_scanned(hist, 0, floors, ground, z_bin)
    assert scanned == [True, False]
    assert levels[0] == 0 and 210 <= levels[1] <= 212  # the storey's bottom
