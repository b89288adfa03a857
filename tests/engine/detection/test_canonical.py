"""Section 3.2: the canonical frame of a space, its entrance rule and the exact round trip to world."""
from __future__ import annotations

import math

import numpy as np
import pytest

from engine.detection.canonical import CanonicalFrame, dominant_yaw, estimate_frame, opening_widths


def _room(rng, size=(6.0, 4.0, 3.0), door=("x-max", 1.0, 2.0), n=15000):
    """Points of an empty box room (canonical axes) with a floor-to-2.1 m doorway in one wall."""
    sx, sy, sz = size
    parts = [rng.uniform([0, 0, 0], [sx, sy, 0], (n, 3)), rng.uniform([0, 0, sz], [sx, sy, sz], (n, 3))]
    for side in ("x-min", "x-max", "y-min", "y-max"):
        p = rng.uniform(0, 1, (n, 3)) * [sx, sy, sz]
        if side.startswith("x"):
            p[:, 0] = 0.0 if side.endswith("min") else sx
            along = 1
        else:
            p[:, 1] = 0.0 if side.endswith("min") else sy
            along = 0
        if door and side == door[0]:
            p = p[~((p[:, along] > door[1]) & (p[:, along] < door[2]) & (p[:, 2] < 2.1))]
        parts.append(p)
    return np.concatenate(parts)


def _place(p, yaw, offset):
    c, s = math.cos(yaw), math.sin(yaw)
    return p @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + offset


def test_unit_cube_round_trip_of_points_and_boxes():
    rng = np.random.default_rng(0)
    f = CanonicalFrame(0.7, [512345.25, 4100000.5, 12.0], [7.5, 4.25, 3.1])
    pts = rng.uniform(-50, 50, (100, 3)) + f.origin
    assert np.allclose(f.from_unit(f.to_unit(pts)), pts, atol=1e-9)
    assert np.allclose(f.from_metric(f.to_metric(pts)), pts, atol=1e-9)
    for _ in range(10):
        p, s = rng.uniform(0, 0.8, 3), rng.uniform(0.01, 0.2, 3)
        center, size, yaw = f.unit_box_to_world(p, s)
        assert yaw == pytest.approx(0.7)
        p2, s2 = f.world_box_to_unit(center, size, yaw)
        assert np.allclose(p2, p, atol=1e-12) and np.allclose(s2, s, atol=1e-12)
        # the same box described with a quarter turn
        p3, s3 = f.world_box_to_unit(center, size[[1, 0, 2]], yaw + math.pi / 2)
        assert np.allclose(p3, p, atol=1e-12) and np.allclose(s3, s, atol=1e-12)
    assert CanonicalFrame.from_json(f.to_json()).to_json() == f.to_json()


@pytest.mark.parametrize("yaw", [0.0, 0.35, -1.2, 2.6])
def test_frame_axes_follow_the_entrance_wall(yaw):
    rng = np.random.default_rng(1)
    local = _room(rng, door=("x-max", 1.0, 2.0))  # doorway in the 4 m wall at x = 6
    world = _place(local, yaw, [100.0, -40.0, 5.0])
    f = estimate_frame(world)
    assert f.entrance == "opening"
    # x runs along the entrance wall (4 m), y across the room (6 m), z up (3 m)
    assert np.allclose(f.extent, [4.0, 6.0, 3.0], atol=0.03)
    u = f.to_unit(world)
    assert u.min() > -0.01 and u.max() < 1.01
    # the doorway wall is at y = 0: the door gap is there
    near = u[np.abs(u[:, 1]) < 0.01]
    gap = near[(near[:, 2] > 0.1) & (near[:, 2] < 0.6)]
    empty = np.bincount(np.clip((gap[:, 0] * 20).astype(int), 0, 19), minlength=20) == 0
    assert empty.sum() >= 4  # the 1 m doorway of the 4 m wall: 5 of 20 bins
    # and the frame's yaw is the room's, turned so that the entrance is its x axis
    turned = (f.yaw - yaw) % (2 * math.pi)
    assert min(abs(turned - math.pi / 2), abs(turned - math.pi / 2 - 2 * math.pi)) < 0.01


def test_no_opening_falls_back_to_the_longest_wall():
    rng = np.random.default_rng(2)
    f = estimate_frame(_room(rng, door=None))
    assert f.entrance == "longest-wall"
    assert f.extent[0] == pytest.approx(6.0, abs=0.03)  # x along the 6 m wall
    assert max(opening_widths(f.to_metric(_room(rng, door=None)), np.zeros(3), f.extent)) == 0


def test_connection_hint_picks_the_nearest_wall_when_no_opening_is_seen():
    rng = np.random.default_rng(3)
    pts = _room(rng, door=None)
    f = estimate_frame(pts, connection=np.array([3.0, 4.2]))  # beyond the y = 4 wall
    assert f.entrance == "neighbour" and f.extent[0] == pytest.approx(6.0, abs=0.03)
    assert f.to_metric(np.array([[3.0, 4.0, 1.0]]))[0, 1] == pytest.approx(0.0, abs=0.03)
    # a visible doorway wins over the hint
    g = estimate_frame(_room(rng, door=("x-max", 1.0, 2.0)), connection=np.array([3.0, 4.2]))
    assert g.entrance == "opening" and g.extent[0] == pytest.approx(4.0, abs=0.03)


def test_dominant_yaw_modulo_quarter_turn():
    rng = np.random.default_rng(4)
    for yaw in (0.1, -0.6, 1.3):
        est = dominant_yaw(_place(_room(rng), yaw, 0))
        d = (est - yaw) % (math.pi / 2)
        assert min(d, math.pi / 2 - d) < 0.01
