"""The CRF's training labels (paper 4.1): which proposals of a space are true elements.

``y*_v = 1`` when proposal ``v`` is a true positive under the evaluation's Pascal VOC rule (3D IoU above
the threshold with a ground-truth box of its class, each box matched at most once, best score first),
with the detection evaluation's own matching.  Design notes: ``docs/design/crf.md``.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from engine.detection.proposals import Proposal
from engine.metrics.boxes import boxes_array
from engine.metrics.precision import match_detections
from tiles.tasks import run_tasks


def proposal_labels(proposals: Sequence[Proposal], ground_truth: Sequence[dict[str, Any]],
                    iou_threshold: float = 0.5) -> np.ndarray:
    """``y*``: True for proposals that are true positives against the ground-truth boxes of their space.

    Parameters
    ----------
    proposals
        Proposals (world ``center``, ``world_size``, ``yaw``, ``class_code``, ``score``).
    ground_truth
        Ground-truth element records (``class_code``, ``center``, ``size``, ``yaw``), e.g. the
        ``elements`` of ``meta/ground_truth`` that belong to this space.
    iou_threshold
        A proposal matches a box when their 3D IoU exceeds this.
    """
    if not 0 < iou_threshold < 1:
        raise ValueError(f"iou_threshold must be in (0, 1), not {iou_threshold}")
    n = len(proposals)
    labels = np.zeros(n, dtype=bool)
    if n == 0:
        return labels
    boxes = np.array([[*p.center, *p.world_size, p.yaw] for p in proposals], dtype=np.float64).reshape(n, 7)
    cls = np.array([p.class_code for p in proposals], dtype=np.int64)
    scores = np.array([p.score for p in proposals], dtype=np.float64)
    gt = list(ground_truth)
    gt_boxes = boxes_array(gt)
    gt_cls = np.array([int(g["class_code"]) for g in gt], dtype=np.int64)
    for c in np.unique(cls):
        d = np.flatnonzero(cls == c)
        g = gt_cls == c
        if g.any():
            labels[d] = match_detections(boxes[d], scores[d], d, gt_boxes[g], iou_threshold)
    return labels


def group_by_space(proposals: Sequence[Proposal], ground_truth: Sequence[dict[str, Any]]
                   ) -> tuple[list[list[Proposal]], list[list[dict[str, Any]]]]:
    """Proposals detected on the ground-truth spaces of one building, with those spaces' ground-truth elements.

    ``proposals`` come from ``engine.detection.detect.detect(store, space_array="gt_space")`` (their
    ``space_id`` is the ground-truth space), ``ground_truth`` is the ``elements`` list of the store's
    ``meta/ground_truth`` (each with its ``space``).  Returns the two lists
    :func:`engine.crf.ssvm.train_crf` takes, one entry per space that has proposals, in space order.
    """
    props: dict[int, list[Proposal]] = {}
    for p in proposals:
        props.setdefault(int(p.space_id), []).append(p)
    gts: dict[int, list[dict[str, Any]]] = {}
    for g in ground_truth:
        gts.setdefault(int(g.get("space", -1)), []).append(g)
    sids = sorted(props)
    return [props[s] for s in sids], [gts.get(s, []) for s in sids]


def _label_task(job: tuple[list[Proposal], list[dict[str, Any]]], iou: float) -> np.ndarray:
    """The labels of one space's ``(proposals, ground truth)``."""
    return proposal_labels(job[0], job[1], iou)


def label_spaces(proposals_per_space: Sequence[Sequence[Proposal]],
                 ground_truth_per_space: Sequence[Sequence[dict[str, Any]]], iou: float,
                 client=None) -> list[np.ndarray]:
    """:func:`proposal_labels` of every space, one dask task per space.

    Parameters
    ----------
    proposals_per_space, ground_truth_per_space
        The proposals and the ground-truth element records of each space.
    iou
        The matching threshold.
    client
        A ``distributed.Client``; None labels the spaces here.
    """
    jobs = [(list(p), list(g)) for p, g in zip(proposals_per_space, ground_truth_per_space)]
    return run_tasks(_label_task, jobs, client=client, label="S-SVM labels", extra_args=(iou,))
