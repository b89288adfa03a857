"""Floor layouts: cells tile the outline exactly, rooms 2.4-15 m wide, hallways 1.8-2.8 m, reshaped rooms."""
from __future__ import annotations

import numpy as np
import pytest
import shapely
from shapely.geometry import box

from engine.synth.layout import ROOM_MAX, ROOM_MIN, floor_layout


@pytest.mark.parametrize("area,seed", [(60, 0), (150, 1), (450, 2), (1200, 3), (3000, 4), (6000, 5)])
def test_cells_tile_the_outline_without_overlap(area, seed):
    lay = floor_layout(np.random.default_rng(seed), area)
    cells = [box(*c) for d in lay.drafts for c in d.cells]
    union = shapely.union_all(cells)
    assert union.area == pytest.approx(lay.length * lay.depth, rel=1e-9)
    assert sum(c.area for c in cells) == pytest.approx(union.area, rel=1e-9)  # no overlap
    assert union.equals(box(0, 0, lay.length, lay.depth))
    assert lay.length * lay.depth == pytest.approx(area, rel=0.1) or area < 100


def test_room_and_hallway_sizes():
    for seed in range(8):
        lay = floor_layout(np.random.default_rng(seed), 900)
        for d in lay.drafts:
            lo = np.min([c[:2] for c in d.cells], axis=0)
            hi = np.max([c[2:] for c in d.cells], axis=0)
            ext = hi - lo
            if d.type == "hallway":
                assert 1.8 <= min(ext) <= 2.8 + 1e-9
            else:
                assert min(ext) >= ROOM_MIN - 1e-9 and max(ext) <= ROOM_MAX + 1e-9, (d.type, ext)


def test_reshaping_makes_open_plans_with_partial_walls_and_l_shapes():
    found_open = found_l = 0
    for seed in range(10):
        lay = floor_layout(np.random.default_rng(seed), 600)
        for d in lay.drafts:
            if d.type == "openspace":
                found_open += 1
                assert len(d.cells) == 2 and len(d.partials) == 1
                (x0, y0), (x1, y1) = d.partials[0]
                assert x0 == x1  # on the old divider, shorter than the room is deep
                depth = d.cells[0][3] - d.cells[0][1]
                assert 0.3 * depth <= abs(y1 - y0) <= 0.7 * depth
            if d.type == "room_l":
                found_l += 1
                shape = shapely.union_all([box(*c) for c in d.cells]).simplify(0)
                assert shape.geom_type == "Polygon" and len(shape.exterior.coords) - 1 == 6
    assert found_open >= 6 and found_l >= 6


@pytest.mark.parametrize("target", [3, 9, 20])
def test_target_count_is_met(target):
    lay = floor_layout(np.random.default_rng(1), target * 31.0, target=target)
    assert len(lay.drafts) == target


def test_upper_floor_takes_the_given_outline():
    lay = floor_layout(np.random.default_rng(3), 0, outline=(40.0, 15.5), lobby=False)
    union = shapely.union_all([box(*c) for d in lay.drafts for c in d.cells])
    assert union.equals(box(0, 0, 40.0, 15.5))
    assert not any(d.type == "lobby" for d in lay.drafts)
