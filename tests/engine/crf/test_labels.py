"""The CRF's training labels: the evaluation's VOC rule, proposals paired with their space's ground truth."""
from __future__ import annotations

import numpy as np
import pytest

from engine.crf.labels import group_by_space, proposal_labels
from engine.detection.proposals import Proposal
from tiles.classes import CLASS_CODES

K = 2
WALL, CHAIR = CLASS_CODES["wall"], CLASS_CODES["chair"]


def world_prop(cls, center, size, score, yaw=0.0):
    c, s = np.asarray(center, float), np.asarray(size, float)
    return Proposal(0, cls, score, c / 10, s / 10, np.ones((K,) * 3, bool), c, s, yaw)


def gt(cls, center, size, yaw=0.0):
    return {"class_code": cls, "center": list(center), "size": list(size), "yaw": yaw}


def test_labels_follow_the_voc_rule():
    g = [gt(WALL, [1, 5, 1.5], [0.2, 8, 3]), gt(CHAIR, [5, 5, 0.45], [0.5, 0.5, 0.9])]
    props = [world_prop(WALL, [1.02, 5, 1.5], [0.2, 8, 3], 0.5),  # matches the wall, but scores lower than...
             world_prop(WALL, [1.0, 5.1, 1.5], [0.2, 8, 3], 0.9),  # ...this one, which takes the box first
             world_prop(WALL, [5, 5, 1.5], [0.2, 8, 3], 2.0),  # nowhere near the wall
             world_prop(CHAIR, [5.05, 5, 0.45], [0.5, 0.5, 0.9], 0.1),  # the chair
             world_prop(CHAIR, [1, 5, 1.5], [0.2, 8, 3], 3.0)]  # wall-shaped "chair": wrong class
    assert proposal_labels(props, g).tolist() == [False, True, False, True, False]
    assert proposal_labels(props, []).tolist() == [False] * 5
    with pytest.raises(ValueError):
        proposal_labels(props, g, iou_threshold=1.5)


def test_group_by_space_pairs_proposals_with_their_spaces_ground_truth():
    a, b, c = (world_prop(WALL, [1, 5, 1.5], [0.2, 8, 3], s) for s in (0.1, 0.2, 0.3))
    a.space_id, b.space_id, c.space_id = 3, 1, 3
    truth = [dict(gt(WALL, [1, 5, 1.5], [0.2, 8, 3]), space=s) for s in (1, 3, 5, 3)]
    props, gts = group_by_space([a, b, c], truth)
    assert props == [[b], [a, c]]
    assert [len(g) for g in gts] == [1, 2] and all(x["space"] == 1 for x in gts[0])
