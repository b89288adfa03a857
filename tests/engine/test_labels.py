"""Point labels from voxelised detection boxes, and the elements.json records."""
from __future__ import annotations

import json
import math

import numpy as np

from engine.labels import _boxes, label_arrays, read_elements_json, write_elements_json
from engine.proposals import Proposal


def _prop(eid, cls, score, center, size, yaw=0.0, occ=None):
    occ = np.ones((2, 2, 2), bool) if occ is None else occ
    return Proposal(space_id=0, class_code=cls, score=score, position=np.zeros(3), size=np.ones(3) * 0.1,
                    occupancy=occ, center=np.asarray(center, float), world_size=np.asarray(size, float), yaw=yaw,
                    element_id=eid)


def test_points_take_the_best_detection_whose_occupied_voxels_hold_them():
    half = np.zeros((2, 2, 2), bool)
    half[:, :, 0] = True  # only the lower half of the box is occupied
    props = [_prop(0, 2, 0.5, [0, 0, 1], [2, 2, 2]),  # wall: the whole box
             _prop(1, 7, 0.9, [0, 0, 1], [2, 2, 2], occ=half),  # table: better, lower half only
             _prop(2, 8, 0.7, [10, 0, 0], [1, 1, 1], yaw=math.pi / 4)]  # chair, turned 45 degrees
    pts = np.array([[0.5, 0.5, 0.5],  # lower half: table wins on score
                    [0.5, 0.5, 1.5],  # upper half: only the wall's occupied sub-box
                    [0.0, 0.0, 2.01],  # just above the box: within the 2 cm margin
                    [0.0, 0.0, 2.1],  # outside: clutter
                    [10.0, 0.65, 0.0],  # inside the turned chair (0.707 reach along a diagonal)
                    [10.45, 0.45, 0.0]])  # inside its axis-aligned bounds but not the turned box
    cls, eid = label_arrays(pts, _boxes(props), margin=0.02)
    assert cls.tolist() == [7, 2, 2, 12, 8, 12]
    assert eid.tolist() == [1, 0, 0, -1, 2, -1]
    assert cls.dtype == np.uint8 and eid.dtype == np.int32


def test_no_detections_means_clutter():
    cls, eid = label_arrays(np.zeros((3, 3)), _boxes([]), margin=0.02)
    assert cls.tolist() == [12, 12, 12] and eid.tolist() == [-1, -1, -1]


def test_elements_json_records(tmp_path):
    props = [_prop(1, 8, 0.7, [10, 2, 0.5], [0.5, 0.6, 1.0], yaw=0.3), _prop(0, 2, 0.5, [0, 0, 1], [4, 0.03, 3])]
    path = write_elements_json(props, tmp_path / "a" / "elements.json")
    recs = read_elements_json(path)
    assert [r["element_id"] for r in recs] == [0, 1]
    assert recs[1]["class"] == "chair" and recs[1]["class_code"] == 8 and recs[1]["yaw"] == 0.3
    assert recs[1]["center"] == [10.0, 2.0, 0.5] and recs[1]["size"] == [0.5, 0.6, 1.0]
    assert len(recs[1]["voxels"]) == 8 and all(len(v) == 6 for v in recs[1]["voxels"])
    assert json.loads((tmp_path / "a" / "elements.json").read_text()) == recs
