"""Doors and boards get their depth from their points: a door box one voxel off the wall reaches the door."""
from __future__ import annotations

import numpy as np
import pytest

from engine import moments as mom
from engine.detection import PointIndex, space_frame
from engine.reveal import RevealSettings, point_span, refine_reveals
from engine.sliding import box_iou
from engine.spacedata import index_spaces, load_space
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
