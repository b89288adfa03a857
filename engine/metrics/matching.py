"""VOC matching split into independent tasks that together equal one global matching.

Predicted and ground-truth spaces differ, so tasks are not spaces as such but *groups of ground-truth spaces*:
every detection is sent to the ground-truth space whose boxes of its class it may overlap, and ground-truth
spaces that one detection may touch together are merged into one group (union-find,
:func:`partition_for_matching`), so no ground-truth box can be matched twice across tasks and the result
equals one global matching exactly.  Only the per-class ``(score, order, tp)`` lists and ground-truth counts
are reduced (:class:`MatchResult`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from engine.metrics.boxes import aabb


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
        da, ga = aabb(det_boxes), aabb(gt_boxes)
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
