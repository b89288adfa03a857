"""Evaluation of element detection (paper section 5.3): VOC average precision and point IoU.

Detection follows the Pascal VOC rules: detections of a class are taken in
decreasing score; each takes the ground-truth box of its class it overlaps
most (3D IoU of yawed boxes, computed exactly); it is a true positive when that
IoU exceeds 0.5 and the box was not taken yet, else a false positive
(duplicates are false positives).  AP is the area under the precision/recall
curve with all-point interpolation (VOC 2010+); mAP is the mean over the 12
element classes that have ground truth.

Matching runs as independent tasks.  Predicted and ground-truth spaces differ,
so tasks are not spaces as such but *groups of ground-truth spaces*: every
detection is sent to the ground-truth space whose boxes of its class it may
overlap, and ground-truth spaces that one detection may touch together are
merged into one group (union-find), so no ground-truth box can be matched twice
across tasks and the result equals one global matching exactly.  Only the
per-class ``(score, order, tp)`` lists and ground-truth counts are reduced.

Point-level: per-tile confusion matrices of ``gt_class`` against
``classification`` are summed into per-class IoU and mIoU.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tiles.classes import CLASS_NAMES, ELEMENT_CLASSES, FURNITURE_CLASSES, STRUCTURAL_CLASSES
from tiles.tasks import run_tasks

N_CLASSES = len(CLASS_NAMES)
N_ELEMENTS = len(ELEMENT_CLASSES)
#: Relative yaws closer than this (radians) to a multiple of 90 degrees are treated as exactly aligned.
YAW_TOL = 1e-9


# -- 3D IoU of yawed boxes ---------------------------------------------------------------------

def boxes_array(records: Sequence[dict[str, Any]]) -> np.ndarray:
    """``(n, 7)`` array ``[cx, cy, cz, dx, dy, dz, yaw]`` of box records (``center``, ``size``, ``yaw``)."""
    out = np.zeros((len(records), 7), dtype=np.float64)
    for i, r in enumerate(records):
        out[i, :3] = r["center"]
        out[i, 3:6] = r["size"]
        out[i, 6] = r.get("yaw", 0.0)
    return out


def _corners_2d(box: np.ndarray) -> np.ndarray:
    """Footprint corners (4, 2) of one box, counter-clockwise."""
    cx, cy, _, dx, dy, _, yaw = box
    c, s = np.cos(yaw), np.sin(yaw)
    local = np.array([[-dx, -dy], [dx, -dy], [dx, dy], [-dx, dy]]) / 2.0
    return local @ np.array([[c, s], [-s, c]]) + [cx, cy]


def _clip_area(subject: np.ndarray, clip: np.ndarray) -> float:
    """Area of the intersection of two convex counter-clockwise polygons (Sutherland-Hodgman)."""
    poly = list(map(tuple, subject))
    m = len(clip)
    for i in range(m):
        if not poly:
            return 0.0
        ax, ay = clip[i]
        bx, by = clip[(i + 1) % m]
        ex, ey = bx - ax, by - ay

        def side(p):
            return ex * (p[1] - ay) - ey * (p[0] - ax)

        out = []
        for j in range(len(poly)):
            p, q = poly[j], poly[(j + 1) % len(poly)]
            sp, sq = side(p), side(q)
            if sp >= 0:
                out.append(p)
            if (sp >= 0) != (sq >= 0):
                t = sp / (sp - sq)
                out.append((p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])))
        poly = out
    if len(poly) < 3:
        return 0.0
    xy = np.asarray(poly)
    x, y = xy[:, 0], xy[:, 1]
    return float(abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) / 2.0)


def box_iou_3d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact 3D IoU of every box of ``a`` ``(n, 7)`` with every box of ``b`` ``(m, 7)``: ``(n, m)``.

    Boxes are ``[cx, cy, cz, dx, dy, dz, yaw]``.  The intersection volume is the
    intersection area of the two rotated footprints times the overlap in z.
    Pairs whose relative yaw is a multiple of 90 degrees (the common case: both
    boxes in one Manhattan frame) are intersected as axis-aligned rectangles in
    that frame, vectorised; other pairs are clipped as polygons (Sutherland-Hodgman).
    """
    a = np.asarray(a, dtype=np.float64).reshape(-1, 7)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 7)
    n, m = len(a), len(b)
    out = np.zeros((n, m))
    if n == 0 or m == 0:
        return out
    # z overlap
    za0, za1 = a[:, 2] - a[:, 5] / 2, a[:, 2] + a[:, 5] / 2
    zb0, zb1 = b[:, 2] - b[:, 5] / 2, b[:, 2] + b[:, 5] / 2
    dz = np.clip(np.minimum(za1[:, None], zb1[None]) - np.maximum(za0[:, None], zb0[None]), 0, None)
    # footprint overlap: quick reject by circumscribed circles
    ra = np.hypot(a[:, 3], a[:, 4]) / 2
    rb = np.hypot(b[:, 3], b[:, 4]) / 2
    dist = np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1])
    cand = (dz > 0) & (dist < ra[:, None] + rb[None])
    rel = b[None, :, 6] - a[:, None, 6]
    quarter = np.round(rel / (np.pi / 2))
    aligned = np.abs(rel - quarter * np.pi / 2) <= YAW_TOL
    area = np.zeros((n, m))
    # aligned pairs: b's footprint in a's frame is an axis-aligned rectangle
    ii, jj = np.nonzero(cand & aligned)
    if len(ii):
        yaw = a[ii, 6]
        c, s = np.cos(yaw), np.sin(yaw)
        rx = b[jj, 0] - a[ii, 0]
        ry = b[jj, 1] - a[ii, 1]
        bx = c * rx + s * ry  # b's centre in a's frame
        by = -s * rx + c * ry
        odd = (quarter[ii, jj].astype(np.int64) % 2) == 1
        bdx = np.where(odd, b[jj, 4], b[jj, 3])
        bdy = np.where(odd, b[jj, 3], b[jj, 4])
        ox = np.minimum(a[ii, 3] / 2, bx + bdx / 2) - np.maximum(-a[ii, 3] / 2, bx - bdx / 2)
        oy = np.minimum(a[ii, 4] / 2, by + bdy / 2) - np.maximum(-a[ii, 4] / 2, by - bdy / 2)
        area[ii, jj] = np.clip(ox, 0, None) * np.clip(oy, 0, None)
    for i, j in zip(*np.nonzero(cand & ~aligned)):
        area[i, j] = _clip_area(_corners_2d(a[i]), _corners_2d(b[j]))
    inter = area * dz
    va = a[:, 3] * a[:, 4] * a[:, 5]
    vb = b[:, 3] * b[:, 4] * b[:, 5]
    union = va[:, None] + vb[None] - inter
    np.divide(inter, union, out=out, where=union > 0)
    return out


def _aabb(boxes: np.ndarray) -> np.ndarray:
    """World axis-aligned bounds ``(n, 6)`` [min xyz, max xyz] of yawed boxes."""
    c, s = np.abs(np.cos(boxes[:, 6])), np.abs(np.sin(boxes[:, 6]))
    hx = (c * boxes[:, 3] + s * boxes[:, 4]) / 2
    hy = (s * boxes[:, 3] + c * boxes[:, 4]) / 2
    h = np.stack([hx, hy, boxes[:, 5] / 2], axis=1)
    return np.concatenate([boxes[:, :3] - h, boxes[:, :3] + h], axis=1)


# -- VOC matching and AP -----------------------------------------------------------------------

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


@dataclass
class MatchResult:
    """What a matching task returns per class: scores, global detection order, TP flags, GT count."""

    scores: dict[int, np.ndarray] = field(default_factory=dict)
    order: dict[int, np.ndarray] = field(default_factory=dict)
    tp: dict[int, np.ndarray] = field(default_factory=dict)
    n_gt: dict[int, int] = field(default_factory=dict)

    def add(self, other: MatchResult) -> MatchResult:
        for c in set(self.scores) | set(other.scores) | set(self.n_gt) | set(other.n_gt):
            for name in ("scores", "order", "tp"):
                d, o = getattr(self, name), getattr(other, name)
                parts = [x for x in (d.get(c), o.get(c)) if x is not None]
                if parts:
                    d[c] = np.concatenate(parts)
            self.n_gt[c] = self.n_gt.get(c, 0) + other.n_gt.get(c, 0)
        return self


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


def _find(parent: np.ndarray, i: int) -> int:
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


def partition_for_matching(det_boxes: np.ndarray, det_cls: np.ndarray, gt_boxes: np.ndarray,
                           gt_cls: np.ndarray, gt_space: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Group ids for detections and GT boxes such that matching per group equals one global matching.

    A detection is linked to every ground-truth space holding a box of its class
    whose bounds meet the detection's bounds; ground-truth spaces linked through
    one detection are merged.  Detections that meet no ground-truth box get group
    -1 (they are false positives whatever happens).
    """
    spaces, gt_group = np.unique(gt_space, return_inverse=True)
    parent = np.arange(len(spaces))
    det_group = np.full(len(det_boxes), -1, dtype=np.int64)
    if len(det_boxes) and len(gt_boxes):
        da, ga = _aabb(det_boxes), _aabb(gt_boxes)
        for c in np.unique(det_cls):
            di = np.nonzero(det_cls == c)[0]
            gi = np.nonzero(gt_cls == c)[0]
            if not len(gi):
                continue
            for start in range(0, len(di), 2048):
                d = di[start:start + 2048]
                meet = np.all((da[d, None, :3] <= ga[None, gi, 3:]) & (ga[None, gi, :3] <= da[d, None, 3:]), axis=2)
                for row in np.nonzero(meet.any(axis=1))[0]:
                    groups = np.unique(gt_group[gi[meet[row]]])
                    r0 = _find(parent, int(groups[0]))
                    for g in groups[1:]:
                        rg = _find(parent, int(g))
                        if rg != r0:
                            parent[rg] = r0
                    det_group[d[row]] = r0
    roots = np.array([_find(parent, i) for i in range(len(spaces))], dtype=np.int64)
    det_group = np.where(det_group >= 0, roots[np.maximum(det_group, 0)], -1)
    return det_group, roots[gt_group] if len(gt_boxes) else np.zeros(0, dtype=np.int64)


@dataclass
class DetectionEvaluation:
    """Per-class AP (NaN: no ground truth), their means and the counts behind them."""

    ap: dict[str, float]
    n_gt: dict[str, int]
    n_det: dict[str, int]
    iou_threshold: float = 0.5

    @property
    def mean_ap(self) -> float:
        return _nanmean([self.ap[c] for c in ELEMENT_CLASSES])

    @property
    def structural_mean(self) -> float:
        return _nanmean([self.ap[c] for c in STRUCTURAL_CLASSES])

    @property
    def furniture_mean(self) -> float:
        return _nanmean([self.ap[c] for c in FURNITURE_CLASSES])

    def to_json(self) -> dict[str, Any]:
        return {"ap": self.ap, "n_gt": self.n_gt, "n_det": self.n_det, "iou_threshold": self.iou_threshold,
                "structural_mean": self.structural_mean, "furniture_mean": self.furniture_mean,
                "mean_ap": self.mean_ap}


def _nanmean(values: Sequence[float]) -> float:
    v = np.asarray(values, dtype=float)
    v = v[~np.isnan(v)]
    return float(v.mean()) if len(v) else float("nan")


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


# -- point level ----------------------------------------------------------------------------

def tile_confusion(tile: Any, store: Any, predicted: str = "classification", truth: str = "gt_class") -> np.ndarray:
    """13 x 13 confusion matrix (rows: truth, columns: prediction) of one tile."""
    cols = store.read(tile, [truth, predicted])
    t = cols[truth].astype(np.int64)
    p = cols[predicted].astype(np.int64)
    ok = (t >= 0) & (t < N_CLASSES) & (p >= 0) & (p < N_CLASSES)
    return np.bincount(t[ok] * N_CLASSES + p[ok], minlength=N_CLASSES ** 2).reshape(N_CLASSES, N_CLASSES)


@dataclass
class PointEvaluation:
    """Point-level per-class IoU from a summed confusion matrix."""

    confusion: np.ndarray

    @property
    def iou(self) -> dict[str, float]:
        cm = self.confusion.astype(np.float64)
        tp = np.diag(cm)
        denom = cm.sum(0) + cm.sum(1) - tp
        vals = np.where(denom > 0, tp / np.where(denom > 0, denom, 1), np.nan)
        return {name: float(v) for name, v in zip(CLASS_NAMES, vals)}

    @property
    def mean_iou(self) -> float:
        """Mean over the 13 classes (S3DIS convention) that occur in truth or prediction."""
        return _nanmean(list(self.iou.values()))

    @property
    def mean_iou_elements(self) -> float:
        return _nanmean([self.iou[c] for c in ELEMENT_CLASSES])

    @property
    def accuracy(self) -> float:
        return float(np.trace(self.confusion) / max(self.confusion.sum(), 1))

    def to_json(self) -> dict[str, Any]:
        return {"iou": self.iou, "mean_iou": self.mean_iou, "mean_iou_elements": self.mean_iou_elements,
                "accuracy": self.accuracy, "confusion": self.confusion.tolist()}


def evaluate_points(store: Any, *, client=None, predicted: str = "classification",
                    truth: str = "gt_class") -> PointEvaluation:
    """Point-level IoU of a store's ``classification`` against ``gt_class``: per-tile confusions, summed."""
    mats = run_tasks(tile_confusion, store.tiles, client=client, label="point confusion",
                     keys=[t.name for t in store.tiles], extra_args=(store, predicted, truth))
    return PointEvaluation(np.sum(mats, axis=0) if mats else np.zeros((N_CLASSES, N_CLASSES), np.int64))


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
