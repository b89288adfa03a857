"""The Manhattan frame estimate recovers a known yaw; the frame maps world <-> aligned both ways."""
from __future__ import annotations

import math

import numpy as np
import pytest

from engine.spaces.alignment import AlignmentSettings, Frame, coarse_yaw, estimate_alignment, orientation_histogram
from tests.engine.handmade import Plan, Room, corridor_plan, sample, transform, write_store


def _angle_error(a_deg: float, b_deg: float, period: float = 90.0) -> float:
    return abs((a_deg - b_deg + period / 2) % period - period / 2)


@pytest.fixture(scope="module")
def points():
    return sample(corridor_plan(4), density=150.0, seed=2)


@pytest.mark.parametrize("yaw", [0.0, 3.7, 30.0, 44.6, 71.25])
def test_alignment_recovers_a_known_yaw(tmp_path, points, yaw):
    xyz, gt = points
    store = write_store(tmp_path / "b.zarr", transform(xyz, yaw, (1000.0, 2000.0, 50.0)), gt)
    al = estimate_alignment(store)
    est = math.degrees(al.frame.yaw)
    assert _angle_error(est, yaw) < 0.05
    # u is the building's longer axis (the corridor, along the plan's x): yaw itself modulo 180
    assert _angle_error(est, yaw, 180.0) < 0.05
    # the per-tile evidence is kept for a later per-wing frame
    assert set(al.tiles) == {t.name for t in store.tiles}
    assert all(len(t["histogram_1deg"]) == 90 for t in al.tiles.values())
    doc = al.to_doc()
    assert doc["frame"]["yaw"] == pytest.approx(al.frame.yaw)


def test_alignment_ignores_clutter_at_other_angles(tmp_path):
    # an L-shaped plan (PCA would tilt) with many boxes turned 20 degrees
    plan = Plan([Room(0, 0, 12, 5), Room(0, 5.2, 5, 14), Room(5.2, 5.2, 12, 9)], [(0, 1, 1.0, 0.9), (0, 2, 1.0, 0.9)])
    xyz, gt = sample(plan, density=150.0, seed=4)
    rng = np.random.default_rng(0)
    boxes = []
    for _ in range(15):
        c = rng.uniform([1, 1], [11, 4])
        p = rng.uniform(-0.6, 0.6, (600, 2))
        p[:300, 0] = np.sign(p[:300, 0]) * 0.6
        p[300:, 1] = np.sign(p[300:, 1]) * 0.6
        a = math.radians(20.0)
        r = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        boxes.append(np.column_stack([p @ r.T + c, rng.uniform(0, 1.2, 600)]))
    xyz = np.vstack([xyz, *boxes])
    gt = np.r_[gt, np.zeros(len(xyz) - len(gt), np.int32)]
    store = write_store(tmp_path / "l.zarr", transform(xyz, 12.0), gt)
    al = estimate_alignment(store)
    assert _angle_error(math.degrees(al.frame.yaw), 12.0) < 0.1


def test_orientation_histogram_peaks_at_the_walls_direction():
    # two long thin walls at 25 degrees, sampled densely, plus a uniform floor
    rng = np.random.default_rng(1)
    t = rng.uniform(0, 8, 20000)
    a = math.radians(25.0)
    walls = [np.column_stack([t * math.cos(a) - off * math.sin(a), t * math.sin(a) + off * math.cos(a)])
             for off in (0.0, 3.0)]
    floor = rng.uniform(-3, 8, (20000, 2))
    h = orientation_histogram(np.vstack(walls + [floor]))
    assert _angle_error(coarse_yaw(h, AlignmentSettings().angle_bin), 25.0) < 0.5


def test_frame_maps_world_to_aligned_and_back():
    f = Frame(math.radians(33.0), (1000.0, 2000.0, 5.0))
    rng = np.random.default_rng(0)
    w = rng.uniform([990, 1990, 0], [1010, 2010, 10], (100, 3))
    a = f.to_aligned(w)
    np.testing.assert_allclose(f.to_world(a), w, atol=1e-9)
    # a step along world direction yaw is a step along u
    step = f.to_aligned(np.array([[1000 + math.cos(f.yaw), 2000 + math.sin(f.yaw), 5.0]]))
    np.testing.assert_allclose(step, [[1.0, 0.0, 0.0]], atol=1e-12)
    assert Frame.from_json(f.to_json()) == f
