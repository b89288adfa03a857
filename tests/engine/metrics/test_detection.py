"""Section 5.3 metrics: exact rotated-box IoU, VOC AP with duplicates and misses, distributed = serial mAP."""
from __future__ import annotations

import math

import numpy as np
import pytest

from engine.metrics.boxes import box_iou_3d
from engine.metrics.detection import evaluate_detections, evaluate_detections_serial
from engine.metrics.matching import partition_for_matching
from engine.metrics.points import PointEvaluation
from engine.metrics.precision import average_precision, match_detections
from tiles.classes import CLASS_CODES


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


def _scene(seed=0, n_spaces=6):
    rng = np.random.default_rng(seed)
    gt, det = [], []
    eid = 0
    for s in range(n_spaces):
        base = np.array([s * 6.0, 0, 0])  # neighbouring spaces 6 m apart: boxes at their border meet
        for _ in range(8):
            c = int(rng.integers(0, 12))
            centre = base + rng.uniform([0, 0, 0], [6, 5, 3])
            size = rng.uniform(0.3, 2.5, 3)
            yaw = float(rng.choice([0.0, 0.3, math.pi / 2]))
            gt.append({"id": eid, "class": "x", "class_code": c, "space": s, "center": centre.tolist(),
                       "size": size.tolist(), "yaw": yaw})
            eid += 1
            for _ in range(int(rng.integers(0, 3))):  # hits, duplicates, near misses
                det.append({"class_code": c, "score": float(rng.uniform()), "yaw": yaw + float(rng.normal(0, 0.05)),
                            "center": (centre + rng.normal(0, 0.25, 3)).tolist(),
                            "size": (size * rng.uniform(0.7, 1.3, 3)).tolist()})
        for _ in range(5):  # false positives anywhere
            det.append({"class_code": int(rng.integers(0, 12)), "score": float(rng.uniform()), "yaw": 0.0,
                        "center": (base + rng.uniform([0, 0, 0], [6, 5, 3])).tolist(),
                        "size": rng.uniform(0.3, 3, 3).tolist()})
    # long detections spanning two spaces
    for s in range(n_spaces - 1):
        det.append({"class_code": CLASS_CODES["wall"], "score": 0.95, "yaw": 0.0,
                    "center": [s * 6.0 + 6.0, 2.5, 1.5], "size": [8.0, 0.3, 3.0]})
    # ties in score across spaces
    for d in det[::7]:
        d["score"] = 0.5
    return gt, det


def test_distributed_map_equals_single_process(client):
    gt, det = _scene()
    serial = evaluate_detections_serial(det, gt)
    local = evaluate_detections(det, gt)
    dist = evaluate_detections(det, gt, client=client)
    for name, ap in serial.ap.items():
        if math.isnan(ap):
            assert math.isnan(local.ap[name]) and math.isnan(dist.ap[name])
        else:
            assert local.ap[name] == pytest.approx(ap, abs=1e-12)
            assert dist.ap[name] == pytest.approx(ap, abs=1e-12)
    assert dist.mean_ap == pytest.approx(serial.mean_ap, abs=1e-12)
    assert 0 < serial.mean_ap < 1


def test_partition_merges_spaces_a_detection_touches():
    gt = np.stack([_box((0, 0, 0)), _box((6, 0, 0)), _box((12, 0, 0))])
    det = np.stack([_box((3, 0, 0), (6, 1, 1)), _box((30, 0, 0))])
    dg, gg = partition_for_matching(det, np.array([2, 2]), gt, np.array([2, 2, 2]), np.array([0, 1, 2]))
    assert gg[0] == gg[1] == dg[0] and gg[2] != gg[0]
    assert dg[1] == -1


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
