"""VOC matching and average precision with duplicates, misses and edge cases."""
from __future__ import annotations

import math

import numpy as np
import pytest

from engine.metrics.precision import average_precision, match_detections


def _box(c=(0, 0, 0), s=(2, 2, 2), yaw=0.0):
    return np.array([*c, *s, yaw], dtype=float)


def test_ap_with_duplicates_and_misses():
    # three chairs; d1 hits g1, d2 duplicates g1, d3 hits g2, d4 hits nothing, g3 is missed
    gt = np.stack([_box((0, 0, 0)), _box((10, 0, 0)), _box((20, 0, 0))])
    det = np.stack([_box((0.1, 0, 0)), _box((0, 0.1, 0)), _box((10, 0.2, 0)), _box((30, 0, 0))])
    scores = np.array([0.9, 0.8, 0.7, 0.6])
    tp = match_detections(det, scores, np.arange(4), gt)
    assert tp.tolist() == [True, False, True, False]
    # precision/recall: (1, 1/3) (1/2, 1/3) (2/3, 2/3) (1/2, 2/3): AP = 1/3 * 1 + 1/3 * 2/3
    assert average_precision(scores, tp, 3) == pytest.approx(5 / 9)


def test_ap_edge_cases():
    assert math.isnan(average_precision(np.array([0.5]), np.array([False]), 0))
    assert average_precision(np.zeros(0), np.zeros(0, bool), 4) == 0.0
    assert average_precision(np.array([1.0, 0.5]), np.array([True, True]), 2) == pytest.approx(1.0)
    # a duplicate ranked below every true positive does not lower AP
    assert average_precision(np.array([1.0, 0.9, 0.1]), np.array([True, True, False]), 2) == pytest.approx(1.0)
