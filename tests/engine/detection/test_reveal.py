"""Doors get their depth from their points (a door box one voxel off the wall reaches the door); columns their sides."""
from __future__ import annotations

import numpy as np
import pytest

from engine.detection import moments as mom
from engine.detection.pointindex import PointIndex
from engine.detection.reveal import RevealSettings, point_span, refine_reveals
from engine.detection.sliding import box_iou
from engine.detection.space import space_frame
from engine.spaces.points import index_spaces, load_space
from engine.synth import generate
from tiles.classes import ELEMENT_CLASSES
from tiles.store import open_store


def test_point_span_is_robust_and_never_thinner_than_asked():
    rng = np.random.default_rng(0)
    v = np.concatenate([rng.uniform(0.05, 0.20, 5000), [0.9, 1.2]])  # two stray points in front
    a, b = point_span(v, 0.2, 0.3, 0.01, 0.05)
    assert a == pytest.approx(0.05, abs=0.01) and b == pytest.approx(0.20, abs=0.01)
    a, b = point_span(np.full(10, 0.4), 0.3, 0.5, 0.01, 0.05)
    assert (a, b) == pytest.approx((0.375, 0.425))
    assert point_span(np.zeros(2), 0.3, 0.5, 0.01, 0.05) == (0.3, 0.5)
    with pytest.raises(ValueError, match="reveal-classes"):
        RevealSettings(classes="doors")


def test_a_door_box_one_voxel_in_front_of_the_wall_reaches_the_door(tmp_path):
    generate(str(tmp_path / "b.zarr"), seed=41, rooms=3, density=1500, yaw=30.0)
    store = open_store(str(tmp_path / "b.zarr"))
    origin = np.asarray(store.meta.origin)
    door = ELEMENT_CLASSES.index("door")
    before, after = [], []
    for ref in index_spaces(store, "gt_space"):
        pts = load_space(store, ref, "gt_space", truth=True)
        frame = space_frame(pts)
        grid = mom.VoxelGrid.covering(frame.extent, 0.1, 2_000_000)
        index = PointIndex(frame.to_metric(pts.xyz), grid)
        for e in store.doc("ground_truth")["elements"]:
            if int(e["space"]) != ref.space_id or int(e["class_code"]) != door:
                continue
            p, s = frame.world_box_to_unit(np.asarray(e["center"]) - origin, e["size"], float(e.get("yaw", 0.0)))
            glo, ghi = p * frame.extent, (p + s) * frame.extent
            a = int(np.argmin(ghi[:2] - glo[:2]))  # the wall's normal
            if ghi[a] - glo[a] > 0.3:
                continue  # an open leaf swung into the room
            vox = grid.voxel
            lo = np.clip(np.round(glo / vox), 0, np.asarray(grid.shape) - 1).astype(np.int64)
            hi = np.clip(np.maximum(np.round(ghi / vox).astype(np.int64), lo + 1), 1, grid.shape)
            # the failure seen on held-out buildings: a one-voxel-deep box in front of the door
            room = 1 if (glo[a] + ghi[a]) / 2 < frame.extent[a] / 2 else -1
            lo[a] = (hi[a] if room > 0 else lo[a] - 1)
            hi[a] = lo[a] + 1
            if lo[a] < 0 or hi[a] > grid.shape[a]:
                continue
            lo_m, hi_m = (lo * vox)[None], (hi * vox)[None]
            before.append(box_iou(lo_m, hi_m, glo, ghi)[0, 0])
            refine_reveals(lo[None], hi[None], lo_m, hi_m, np.array([door]), grid, index,
                           RevealSettings(classes=("door",)))
            after.append(box_iou(lo_m, hi_m, glo, ghi)[0, 0])
            assert np.allclose(lo_m[0, [1 - a, 2]], lo[[1 - a, 2]] * vox[[1 - a, 2]])  # along the wall: unchanged
    assert len(after) >= 2
    assert max(before) < 0.5
    assert np.mean(np.array(after) >= 0.5) >= 0.75, (before, after)


def _faces(rng, x0, x1, y0, y1, faces, n=4000):
    """Points on the named vertical faces ('x0', 'x1', 'y0', 'y1') of a box from z 0 to 3 m."""
    out = []
    for f in faces:
        z = rng.uniform(0, 3, n)
        if f[0] == "x":
            out.append(np.column_stack([np.full(n, x0 if f == "x0" else x1), rng.uniform(y0, y1, n), z]))
        else:
            out.append(np.column_stack([rng.uniform(x0, x1, n), np.full(n, y0 if f == "y0" else y1), z]))
    return np.concatenate(out)


def test_solid_sides_move_to_the_faces_where_the_points_stop():
    """A column's sides come from its faces; beside a pilaster's wall the window's side stays."""
    rng = np.random.default_rng(3)
    free = _faces(rng, 1.05, 1.40, 1.05, 1.30, ("x0", "x1", "y0", "y1"))
    pilaster = _faces(rng, 2.05, 2.40, 2.25, 2.49, ("x0", "x1", "y0"))
    wall = np.column_stack([rng.uniform(0, 3, 40000), rng.uniform(2.49, 2.5, 40000), rng.uniform(0, 3, 40000)])
    floor = np.column_stack([rng.uniform(0, 3, 40000), rng.uniform(0, 3, 40000), rng.uniform(0, 0.01, 40000)])
    pts = np.concatenate([free, pilaster, wall, floor])
    grid = mom.VoxelGrid.covering(np.array([3.0, 3.0, 3.0]), 0.1, 2_000_000)
    index = PointIndex(pts, grid)
    column = ELEMENT_CLASSES.index("column")
    lo = np.array([[10, 10, 0], [20, 22, 0]])  # a voxel too wide on each side; the pilaster's box
    hi = np.array([[15, 14, 30], [25, 25, 30]])
    lo_m, hi_m = lo * 0.1, hi * 0.1
    settings = RevealSettings(classes=(), solid_classes=("column",))
    refine_reveals(lo, hi, lo_m, hi_m, np.array([column, column]), grid, index, settings)
    np.testing.assert_allclose(lo_m[0, :2], [1.05, 1.05], atol=0.01)
    np.testing.assert_allclose(hi_m[0, :2], [1.40, 1.30], atol=0.01)
    np.testing.assert_allclose([lo_m[1, 1], hi_m[1, 1]], [2.25, 2.5], atol=0.01)  # front face to the wall
    np.testing.assert_allclose([lo_m[1, 0], hi_m[1, 0]], [2.0, 2.5])  # the wall runs on along x: kept
    np.testing.assert_allclose(lo_m[:, 2], 0.0)  # heights unchanged
    np.testing.assert_allclose(hi_m[:, 2], 3.0)
    with pytest.raises(ValueError, match="solid-classes"):
        RevealSettings(solid_classes="pillar")
