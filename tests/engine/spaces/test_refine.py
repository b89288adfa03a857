"""Refinement of large spaces in their own frame: orientations, regions, the memory store, relabelling."""
from __future__ import annotations

import math

import numpy as np

from engine.spaces.alignment import AlignmentSettings, Frame
from engine.spaces.histograms import Grid
from engine.spaces.refine import MemoryStore, Part, Refinement, frame_regions, relabel, space_yaw, two_orientations


def _room_walls(x0: float, y0: float, x1: float, y1: float, step: float, rng, per_m: int = 400) -> np.ndarray:
    """Points on the four walls of a rectangle and on the parallel inner walls every ``step`` metres."""
    pts = []
    xs = np.arange(x0, x1 + 1e-9, step)
    for x in xs:
        y = rng.uniform(y0, y1, int(per_m * (y1 - y0)))
        pts.append(np.stack([x + rng.normal(0, 0.01, len(y)), y], axis=1))
    for y in (y0, y1):
        x = rng.uniform(x0, x1, int(per_m * (x1 - x0)))
        pts.append(np.stack([x, y + rng.normal(0, 0.01, len(x))], axis=1))
    return np.concatenate(pts)


def _floor(x0, y0, x1, y1, rng, per_m2: int = 30) -> np.ndarray:
    n = int(per_m2 * (x1 - x0) * (y1 - y0))
    return np.stack([rng.uniform(x0, x1, n), rng.uniform(y0, y1, n)], axis=1)


def _turn(xy: np.ndarray, deg: float, about=(0.0, 0.0)) -> np.ndarray:
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    p = xy - about
    return np.stack([c * p[:, 0] - s * p[:, 1], s * p[:, 0] + c * p[:, 1]], axis=1) + about


def _two_blocks(rng) -> tuple[np.ndarray, np.ndarray]:
    """A block of rooms along the axes (x 0-20) and a wing of rooms turned by 30 degrees (x ~ 26-40)."""
    main = np.concatenate([_room_walls(0, 0, 20, 12, 5.0, rng), _floor(0, 0, 20, 12, rng)])
    wing = np.concatenate([_room_walls(0, 0, 12, 10, 4.0, rng), _floor(0, 0, 12, 10, rng)])
    wing = _turn(wing, 30.0) + [28.0, -2.0]
    return main, wing


def test_two_orientations_finds_a_strong_second_peak_only():
    h = np.zeros(180)  # 0.5 degree bins
    h[20], h[21] = 60.0, 40.0  # 10-10.5 degrees
    h[80] = 70.0  # 40 degrees
    got = two_orientations(h, 0.5, separation=5.0, half_width=2.0, min_second=0.5)
    assert len(got) == 2
    assert abs(got[0] - 10.5) < 0.5 and abs(got[1] - 40.25) < 0.5
    h[80] = 30.0  # less than half the first
    assert len(two_orientations(h, 0.5, separation=5.0, half_width=2.0, min_second=0.5)) == 1
    # near the first (within the separation): not a second orientation
    h[80], h[26] = 0.0, 80.0
    assert len(two_orientations(h, 0.5, separation=5.0, half_width=2.0, min_second=0.5)) == 1
    assert two_orientations(np.zeros(180), 0.5, 5.0, 2.0, 0.5) == []


def test_space_yaw_estimates_a_turned_space_and_snaps_to_the_building():
    rng = np.random.default_rng(0)
    _, wing = _two_blocks(rng)
    p = AlignmentSettings()
    yaw = math.degrees(space_yaw(wing, p, building_yaw=0.0, snap_deg=2.0))
    assert abs(yaw - 30.0) < 0.3
    # the direction closest to the building's among yaw + k 90
    yaw = math.degrees(space_yaw(wing, p, building_yaw=math.radians(100.0), snap_deg=2.0))
    assert abs(yaw - 120.0) < 0.3
    # within the snap angle: exactly the building's yaw
    b = math.radians(29.0)
    assert space_yaw(wing, p, building_yaw=b, snap_deg=2.0) == b


def test_frame_regions_split_a_block_and_its_turned_wing():
    rng = np.random.default_rng(1)
    main, wing = _two_blocks(rng)
    xy = np.concatenate([main, wing])
    reg = frame_regions(xy, AlignmentSettings(), [0.0, 30.0], tolerance=2.0, block=0.5, smooth=1.5)
    lab_main, lab_wing = reg.of(main), reg.of(wing)
    assert np.mean(lab_main == 0) > 0.95
    assert np.mean(lab_wing == 1) > 0.95


def test_memory_store_gives_the_bins_of_the_real_coordinates():
    rng = np.random.default_rng(2)
    scale, offset, origin = (0.001, 0.001, 0.001), (1000.0, 2000.0, 10.0), (1005.0, 2003.0, 10.0)
    raw = {a: rng.integers(0, 20000, 500).astype(np.int32) for a in "xyz"}
    mem = MemoryStore(raw, scale, offset, origin)
    assert mem.meta.point_count == 500 and mem.tiles[0].count == 500
    xy = mem.xy_local()
    assert np.allclose(xy[:, 0], raw["x"] * 0.001 + 1000.0 - 1005.0)
    grid = Grid.for_store(mem, Frame(0.3, origin), 0.01, 0.02)
    bu, bv, bz = grid.tile_bins(mem, "memory")
    u = math.cos(0.3) * xy[:, 0] + math.sin(0.3) * xy[:, 1]
    assert np.mean(bu == np.floor(u / 0.01)) > 0.99  # floating rounding at bin edges aside


def test_memory_store_computes_the_bins_once_per_grid():
    """The refinement's passes share one copy of the bins (read-only) instead of computing them per pass."""
    rng = np.random.default_rng(3)
    origin = (1005.0, 2003.0, 10.0)
    raw = {a: rng.integers(0, 20000, 500).astype(np.int32) for a in "xyz"}
    mem = MemoryStore(raw, (0.001, 0.001, 0.001), (1000.0, 2000.0, 10.0), origin)
    grid = Grid.for_store(mem, Frame(0.3, origin), 0.01, 0.02)
    first = grid.tile_bins(mem, "memory")
    assert grid.tile_bins(mem, "memory") is first  # the same arrays, not computed again
    plain = grid.raw_bins(raw, grid.raw_affine(mem.meta))
    assert all(np.array_equal(a, b) and not a.flags.writeable for a, b in zip(first, plain))
    other = Grid.for_store(mem, Frame(0.5, origin), 0.01, 0.02)  # another frame: computed for it
    turned = other.tile_bins(mem, "memory")
    assert turned is not first and np.array_equal(turned[0], other.raw_bins(raw, other.raw_affine(mem.meta))[0])


def test_relabel_moves_only_the_refined_spaces_points_into_the_new_cells():
    from engine.spaces.slicing import Box

    scale, offset, origin = (0.01, 0.01, 0.01), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    # four points: two in building cell 0 (refined), one in cell 1 (not), one outside every cell
    raw = {"x": np.array([100, 300, 500, 700]), "y": np.array([50, 50, 50, 50]), "z": np.array([100, 100, 100, 100])}
    cell = np.array([0, 0, 1, -1])
    grid = Grid(Frame(0.0, origin), 0.01, 0.02)
    part = Part(0.0, [Box(0, 0, 200, 0, 100), Box(0, 200, 400, 0, 100)], np.array([0, 1]))
    ref = Refinement(7, 0, [part])
    idx = part.index((0, 200))
    owner = np.array([-1, 0, -1])  # owner[cell + 1]: building cell 0 belongs to refinement 0
    new = relabel(cell, raw, type("M", (), {"scale": scale, "offset": offset, "origin": origin})(),
                  [(ref, [(grid, idx, 10)])], owner)
    assert new.tolist() == [10, 11, 1, -1]
