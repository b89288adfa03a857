"""VOC matching of one class's detections and average precision (paper section 5.3).

Detections of a class are taken in decreasing score; each takes the ground-truth box of its class it overlaps
most (3D IoU of yawed boxes, computed exactly); it is a true positive when that IoU exceeds 0.5 and the box was
not taken yet, else a false positive (duplicates are false positives).  AP is the area under the
precision/recall curve with all-point interpolation (VOC 2010+).
"""
from __future__ import annotations

import numpy as np

from engine.metrics.boxes import box_iou_3d


def match_detections(det_boxes: np.ndarray, det_scores: np.ndarray, det_order: np.ndarray,
                     gt_boxes: np.ndarray, iou_threshold: float = 0.5) -> np.ndarray:
    """VOC greedy matching of one class: a bool TP flag per detection.

    Detections are taken by decreasing score (ties by ``det_order``); each is a
    true positive when its best-overlapping ground-truth box has IoU above the
    threshold and is not yet taken.
    """
    n = len(det_scores)
    tp = np.zeros(n, dtype=bool)
    if n == 0 or len(gt_boxes) == 0:
        return tp
    iou = box_iou_3d(det_boxes, gt_boxes)
    taken = np.zeros(len(gt_boxes), dtype=bool)
    for i in np.lexsort((det_order, -det_scores)):
        j = int(np.argmax(iou[i]))
        if iou[i, j] > iou_threshold and not taken[j]:
            taken[j] = True
            tp[i] = True
    return tp


def average_precision(scores: np.ndarray, tp: np.ndarray, n_gt: int,
                      order: np.ndarray | None = None) -> float:
    """VOC all-point interpolated AP from per-detection scores and TP flags; NaN without ground truth."""
    if n_gt <= 0:
        return float("nan")
    scores = np.asarray(scores, dtype=np.float64)
    tp = np.asarray(tp, dtype=bool)
    if len(scores) == 0:
        return 0.0
    order = np.arange(len(scores)) if order is None else np.asarray(order)
    idx = np.lexsort((order, -scores))
    ctp = np.cumsum(tp[idx])
    cfp = np.cumsum(~tp[idx])
    rec = ctp / n_gt
    prec = ctp / np.maximum(ctp + cfp, 1e-300)
    mrec = np.concatenate([[0.0], rec, [1.0]])
    mpre = np.concatenate([[0.0], prec, [0.0]])
    mpre = np.maximum.accumulate(mpre[::-1])[::-1]
    steps = np.nonzero(mrec[1:] != mrec[:-1])[0]
    return float(np.sum((mrec[steps + 1] - mrec[steps]) * mpre[steps + 1]))
