"""Exact 3D IoU of yawed boxes against hand values, in any frame."""
from __future__ import annotations

import math

import numpy as np
import pytest

from engine.metrics.boxes import box_iou_3d


def _box(c=(0, 0, 0), s=(2, 2, 2), yaw=0.0):
    return np.array([*c, *s, yaw], dtype=float)


@pytest.mark.parametrize("b, expected", [
    (_box(), 1.0),
    (_box((1, 0, 0), yaw=math.pi / 2), 1 / 3),  # aligned up to a quarter turn, half overlap in x
    (_box((0, 0, 1)), 1 / 3),  # half overlap in z
    (_box(yaw=math.pi / 4), 8 * (math.sqrt(2) - 1) * 2 / (16 - 8 * (math.sqrt(2) - 1) * 2)),  # octagon
    (_box((1, 0, 0.5), yaw=math.pi / 4), (2 * math.sqrt(2) - 1) * 1.5 / (16 - (2 * math.sqrt(2) - 1) * 1.5)),
    (_box((5, 0, 0)), 0.0),
])
def test_rotated_iou_against_hand_values(b, expected):
    a = _box()
    assert box_iou_3d(a, b)[0, 0] == pytest.approx(expected, abs=1e-9)
    assert box_iou_3d(b, a)[0, 0] == pytest.approx(expected, abs=1e-9)


def test_rotated_iou_of_equal_boxes_in_any_frame():
    rng = np.random.default_rng(3)
    for _ in range(20):
        b = _box(rng.normal(size=3) * 10, rng.uniform(0.1, 5, 3), rng.uniform(-4, 4))
        moved = b.copy()
        moved[6] += math.pi  # a half turn is the same box
        assert box_iou_3d(b, moved)[0, 0] == pytest.approx(1.0)
        assert box_iou_3d(b, b + [0, 0, 0, 0, 0, 0, 0.3])[0, 0] < 1.0
