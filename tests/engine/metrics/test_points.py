"""Point-level IoU from a confusion matrix."""
from __future__ import annotations

import math

import numpy as np
import pytest

from engine.metrics.points import PointEvaluation


def test_point_iou_from_confusion():
    cm = np.zeros((13, 13), dtype=np.int64)
    cm[0, 0], cm[0, 1], cm[1, 1], cm[12, 12], cm[12, 0] = 8, 2, 5, 10, 2
    ev = PointEvaluation(cm)
    assert ev.iou["ceiling"] == pytest.approx(8 / 12)
    assert ev.iou["floor"] == pytest.approx(5 / 7)
    assert ev.iou["clutter"] == pytest.approx(10 / 12)
    assert math.isnan(ev.iou["wall"])
    assert ev.mean_iou == pytest.approx(np.mean([8 / 12, 5 / 7, 10 / 12]))
    assert ev.accuracy == pytest.approx(23 / 27)
