"""Matching split into groups of ground-truth spaces: the spaces one detection touches are one group."""
from __future__ import annotations

import numpy as np

from engine.metrics.matching import partition_for_matching


def _box(c=(0, 0, 0), s=(2, 2, 2), yaw=0.0):
    return np.array([*c, *s, yaw], dtype=float)


def test_partition_merges_spaces_a_detection_touches():
    gt = np.stack([_box((0, 0, 0)), _box((6, 0, 0)), _box((12, 0, 0))])
    det = np.stack([_box((3, 0, 0), (6, 1, 1)), _box((30, 0, 0))])
    dg, gg = partition_for_matching(det, np.array([2, 2]), gt, np.array([2, 2, 2]), np.array([0, 1, 2]))
    assert gg[0] == gg[1] == dg[0] and gg[2] != gg[0]
    assert dg[1] == -1
