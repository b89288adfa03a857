"""Evaluation of element detection (paper section 5.3): VOC average precision per class and mAP.

Detections are matched to ground-truth boxes under the Pascal VOC rules (:mod:`engine.metrics.precision`) as
independent dask tasks, one per group of ground-truth spaces (:mod:`engine.metrics.matching`); AP per class
comes from the reduced lists.  mAP is the mean over the 12 element classes that have ground truth.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from engine.metrics.boxes import boxes_array
from engine.metrics.matching import MatchResult, partition_for_matching
from engine.metrics.means import nanmean
from engine.metrics.precision import average_precision, match_detections
from tiles.classes import ELEMENT_CLASSES, FURNITURE_CLASSES, STRUCTURAL_CLASSES
from tiles.tasks import run_tasks

N_ELEMENTS = len(ELEMENT_CLASSES)


def _match_group(job: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                 iou_threshold: float) -> MatchResult:
    """One matching task: all detections and GT boxes of a group of ground-truth spaces."""
    det_boxes, det_cls, det_scores, det_order, gt_boxes, gt_cls = job
    res = MatchResult()
    for c in range(N_ELEMENTS):
        dm, gm = det_cls == c, gt_cls == c
        res.n_gt[c] = int(gm.sum())
        if dm.any():
            res.scores[c] = det_scores[dm]
            res.order[c] = det_order[dm]
            res.tp[c] = match_detections(det_boxes[dm], det_scores[dm], det_order[dm], gt_boxes[gm],
                                         iou_threshold)
    return res


@dataclass
class DetectionEvaluation:
    """Per-class AP (NaN: no ground truth), their means and the counts behind them."""

    ap: dict[str, float]
    n_gt: dict[str, int]
    n_det: dict[str, int]
    iou_threshold: float = 0.5

    @property
    def mean_ap(self) -> float:
        return nanmean([self.ap[c] for c in ELEMENT_CLASSES])

    @property
    def structural_mean(self) -> float:
        return nanmean([self.ap[c] for c in STRUCTURAL_CLASSES])

    @property
    def furniture_mean(self) -> float:
        return nanmean([self.ap[c] for c in FURNITURE_CLASSES])

    def to_json(self) -> dict[str, Any]:
        return {"ap": self.ap, "n_gt": self.n_gt, "n_det": self.n_det, "iou_threshold": self.iou_threshold,
                "structural_mean": self.structural_mean, "furniture_mean": self.furniture_mean,
                "mean_ap": self.mean_ap}



def _as_arrays(detections: Sequence[Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Boxes, class codes and scores of Proposals or ``elements.json`` records."""
    boxes = np.zeros((len(detections), 7))
    cls = np.zeros(len(detections), dtype=np.int64)
    scores = np.zeros(len(detections))
    for i, d in enumerate(detections):
        if isinstance(d, dict):
            boxes[i, :3], boxes[i, 3:6], boxes[i, 6] = d["center"], d["size"], d.get("yaw", 0.0)
            cls[i], scores[i] = d["class_code"], d["score"]
        else:
            boxes[i, :3], boxes[i, 3:6], boxes[i, 6] = d.center, d.world_size, d.yaw
            cls[i], scores[i] = d.class_code, d.score
    return boxes, cls, scores


def evaluate_detections(detections: Sequence[Any], ground_truth: Sequence[dict[str, Any]], *,
                        client=None, iou_threshold: float = 0.5) -> DetectionEvaluation:
    """AP per class and mAP of detections against ground-truth element boxes, matched as dask tasks.

    Parameters
    ----------
    detections
        :class:`engine.detection.proposals.Proposal` objects or ``elements.json`` records (world boxes).
    ground_truth
        The ``elements`` of a store's ``meta/ground_truth`` document (world boxes, ``space``).
    client
        A ``distributed.Client``; None matches here, group by group.
    iou_threshold
        A detection is a true positive when its IoU with the box exceeds this.
    """
    det_boxes, det_cls, det_scores = _as_arrays(detections)
    gt = [g for g in ground_truth if 0 <= int(g["class_code"]) < N_ELEMENTS]
    gt_boxes = boxes_array(gt)
    gt_cls = np.array([int(g["class_code"]) for g in gt], dtype=np.int64)
    gt_space = np.array([int(g.get("space", -1)) for g in gt], dtype=np.int64)
    keep = (det_cls >= 0) & (det_cls < N_ELEMENTS)
    det_order = np.arange(len(det_boxes))
    det_boxes, det_cls, det_scores, det_order = det_boxes[keep], det_cls[keep], det_scores[keep], det_order[keep]
    det_group, gt_group = partition_for_matching(det_boxes, det_cls, gt_boxes, gt_cls, gt_space)
    groups = np.unique(np.concatenate([gt_group, det_group[det_group >= 0]]))
    jobs = []
    for g in groups:
        dm, gm = det_group == g, gt_group == g
        jobs.append((det_boxes[dm], det_cls[dm], det_scores[dm], det_order[dm], gt_boxes[gm], gt_cls[gm]))
    results = run_tasks(_match_group, jobs, client=client, label="match detections",
                        keys=[int(g) for g in groups], extra_args=(iou_threshold,))
    total = MatchResult()
    for r in results:
        total.add(r)
    lone = det_group < 0  # detections meeting no ground-truth box: false positives
    for c in range(N_ELEMENTS):
        m = lone & (det_cls == c)
        if m.any():
            total.add(MatchResult(scores={c: det_scores[m]}, order={c: det_order[m]},
                                  tp={c: np.zeros(int(m.sum()), dtype=bool)}, n_gt={}))
    return reduce_matches(total, iou_threshold)


def reduce_matches(total: MatchResult, iou_threshold: float = 0.5) -> DetectionEvaluation:
    """Per-class AP from the reduced (score, order, TP) lists and ground-truth counts."""
    ap, n_gt, n_det = {}, {}, {}
    for c, name in enumerate(ELEMENT_CLASSES):
        s = total.scores.get(c, np.zeros(0))
        ap[name] = average_precision(s, total.tp.get(c, np.zeros(0, bool)), total.n_gt.get(c, 0),
                                     total.order.get(c))
        n_gt[name] = int(total.n_gt.get(c, 0))
        n_det[name] = int(len(s))
    return DetectionEvaluation(ap, n_gt, n_det, iou_threshold)


def evaluate_detections_serial(detections: Sequence[Any], ground_truth: Sequence[dict[str, Any]],
                               iou_threshold: float = 0.5) -> DetectionEvaluation:
    """The same evaluation as one global matching in this process (the reference for tests)."""
    det_boxes, det_cls, det_scores = _as_arrays(detections)
    gt = [g for g in ground_truth if 0 <= int(g["class_code"]) < N_ELEMENTS]
    gt_boxes = boxes_array(gt)
    gt_cls = np.array([int(g["class_code"]) for g in gt], dtype=np.int64)
    res = _match_group((det_boxes, det_cls, det_scores, np.arange(len(det_boxes)), gt_boxes, gt_cls),
                       iou_threshold)
    return reduce_matches(res, iou_threshold)



def format_ap_table(results: Sequence[dict[str, Any]], names: Sequence[str] | None = None) -> str:
    """A Table-3-style text table (AP in %) of :meth:`DetectionEvaluation.to_json` results, one row each."""
    cols = list(STRUCTURAL_CLASSES) + ["struct."] + list(FURNITURE_CLASSES) + ["furn.", "mAP"]
    names = list(names) if names is not None else [r.get("name", "") for r in results]
    width = max([len(n) for n in names] + [4])
    lines = [" " * width + "  " + " ".join(f"{c[:8]:>8}" for c in cols)]
    for name, r in zip(names, results):
        vals = [r["ap"][c] for c in STRUCTURAL_CLASSES] + [r["structural_mean"]] + \
               [r["ap"][c] for c in FURNITURE_CLASSES] + [r["furniture_mean"], r["mean_ap"]]
        lines.append(f"{name:<{width}}  " + " ".join("     n/a" if v != v else f"{100 * v:8.2f}" for v in vals))
    return "\n".join(lines)
