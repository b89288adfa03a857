"""Point labels from detection boxes (whole or voxelised, some classes first), and the elements.json records."""
from __future__ import annotations

import json
import math

import numpy as np

from engine.detection.proposals import Proposal
from engine.outputs.labels import _boxes, label_arrays, read_elements_json, write_elements_json


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


# -- the bucketed implementation against a brute-force reference ---------------------------------

def _reference(xyz, boxes, margin, space=None, first=()):
    """Every box in turn (the ``first`` classes' boxes, then the others; each group best score first, ties in
    input order) against every point; a point keeps the first box that holds it."""
    from engine.outputs.labels import _world_bounds

    n = len(xyz)
    cls = np.full(n, 12, np.uint8)
    eid = np.full(n, -1, np.int32)
    taken = np.zeros(n, bool)
    if not len(boxes["score"]):
        return cls, eid
    bounds = _world_bounds(boxes, margin)
    k = boxes["occ"].shape[1]
    ahead = [i for i in np.argsort(-boxes["score"], kind="stable") if boxes["cls"][i] in first]
    rest = [i for i in np.argsort(-boxes["score"], kind="stable") if boxes["cls"][i] not in first]
    for i in ahead + rest:
        if not boxes["score"][i] > -np.inf:
            continue
        lo, hi = bounds[i, :3], bounds[i, 3:]
        in_bounds = np.all((xyz >= lo) & (xyz <= hi), axis=1)
        c, s = np.cos(boxes["yaw"][i]), np.sin(boxes["yaw"][i])
        d = xyz - boxes["center"][i]
        local = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)
        size = np.maximum(boxes["size"][i], 1e-9)
        rel = local + size / 2
        inside = np.all((rel >= -margin) & (rel <= size + margin), axis=1)
        cell = np.clip(np.floor(rel / size * k).astype(np.int64), 0, k - 1)
        occ = boxes["occ"][i][cell[:, 0], cell[:, 1], cell[:, 2]]
        take = in_bounds & inside & occ & ~taken
        if space is not None:
            take &= space == boxes["space"][i]
        taken |= take
        cls[take] = boxes["cls"][i]
        eid[take] = boxes["eid"][i]
    return cls, eid


def _random_case(seed, n_boxes=40, n_points=3000, k=4, occupied=True):
    rng = np.random.default_rng(seed)
    props = []
    scores = np.round(rng.uniform(-1, 1, n_boxes), 1)  # one decimal: many exact ties
    for i in range(n_boxes):
        size = rng.uniform(0.05, 3.0, 3) * rng.choice([1.0, 0.1], 3, p=[0.8, 0.2])  # some thin boxes
        occ = rng.random((k, k, k)) < rng.uniform(0.3, 1.0)
        props.append(_prop(i, int(rng.integers(0, 12)), float(scores[i]), rng.uniform(-3, 3, 3), size,
                           yaw=float(rng.choice([0.0, np.pi / 2, rng.uniform(-np.pi, np.pi)])), occ=occ))
        props[-1].space_id = int(rng.integers(0, 3))
    pts = rng.uniform(-5, 5, (n_points, 3))
    # points exactly on box faces and on bucket-cell boundaries
    for p in props[:10]:
        pts[rng.integers(0, n_points)] = p.center + p.world_size / 2
        pts[rng.integers(0, n_points)] = p.center - p.world_size / 2
    pts[:50] = np.round(pts[:50] * 2) / 2
    return pts, _boxes(props, occupied), rng.integers(0, 3, n_points)


def test_bucketed_labels_equal_the_brute_force_rule():
    for seed in range(12):
        pts, boxes, _ = _random_case(seed, k=2 + seed % 3)
        for margin in (0.0, 0.02, 0.3):
            cls, eid = label_arrays(pts, boxes, margin)
            ref_cls, ref_eid = _reference(pts, boxes, margin)
            assert np.array_equal(cls, ref_cls) and np.array_equal(eid, ref_eid), (seed, margin)
            assert (cls != 12).sum() > 100  # the case exercises overlaps, not just clutter


def test_labels_do_not_depend_on_cell_size_or_batching(monkeypatch):
    import engine.outputs.labels as labels

    pts, boxes, space = _random_case(3, n_boxes=60)
    want = _reference(pts, boxes, 0.02)
    want_own = _reference(pts, boxes, 0.02, space=space)
    monkeypatch.setattr(labels, "PAIR_BATCH", 97)
    monkeypatch.setattr(labels, "POINT_BATCH", 501)
    for cell in (0.05, 0.37, 2.0, 50.0):
        got = label_arrays(pts, boxes, 0.02, cell=cell)
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1]), cell
        got = label_arrays(pts, boxes, 0.02, cell=cell, space=space)
        assert np.array_equal(got[0], want_own[0]) and np.array_equal(got[1], want_own[1]), cell
    monkeypatch.setattr(labels, "DENSE_CELLS", 10)  # a binary search for the cells
    got = label_arrays(pts, boxes, 0.02, cell=0.05)
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
    monkeypatch.setattr(labels, "CELL_BUDGET", 50)  # the grid must coarsen to hold the boxes
    got = label_arrays(pts, boxes, 0.02, cell=0.05)
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])


def test_ties_go_to_the_first_box_and_unscored_boxes_label_nothing():
    props = [_prop(5, 2, 0.5, [0, 0, 0], [2, 2, 2]), _prop(6, 3, 0.5, [0, 0, 0], [2, 2, 2]),
             _prop(7, 4, float("nan"), [3, 0, 0], [2, 2, 2]), _prop(8, 5, -np.inf, [3, 0, 0], [2, 2, 2]),
             _prop(9, 6, np.inf, [6, 0, 0], [2, 2, 2]), _prop(10, 7, np.inf, [6, 0, 0], [2, 2, 2])]
    pts = np.array([[0.0, 0, 0], [3, 0, 0], [6, 0, 0]])
    cls, eid = label_arrays(pts, _boxes(props), margin=0.0)
    assert eid.tolist() == [5, -1, 9] and cls.tolist() == [2, 12, 6]
    ref = _reference(pts, _boxes(props), 0.0)
    assert eid.tolist() == ref[1].tolist()
    # the same boxes in the other order: the other of each tied pair wins
    cls, eid = label_arrays(pts, _boxes(props[::-1]), margin=0.0)
    assert eid.tolist() == [6, -1, 10]


def test_empty_inputs():
    pts, boxes, _ = _random_case(0)
    for xyz, b in ((np.zeros((0, 3)), boxes), (pts, _boxes([])), (np.zeros((0, 3)), _boxes([]))):
        cls, eid = label_arrays(xyz, b, 0.02)
        assert len(cls) == len(xyz) and (cls == 12).all() and (eid == -1).all()
        assert cls.dtype == np.uint8 and eid.dtype == np.int32
    unscored = _boxes([_prop(0, 2, -np.inf, [0, 0, 0], [20, 20, 20])])
    assert (label_arrays(pts, unscored, 0.02)[1] == -1).all()


def test_own_space_restricts_a_box_to_the_points_of_its_space():
    pts, boxes, space = _random_case(5)
    free = label_arrays(pts, boxes, 0.02)
    own = label_arrays(pts, boxes, 0.02, space=space)
    ref = _reference(pts, boxes, 0.02, space=space)
    assert np.array_equal(own[0], ref[0]) and np.array_equal(own[1], ref[1])
    labelled = own[1] >= 0
    assert (boxes["space"][own[1][labelled]] == space[labelled]).all()  # element ids are box indices here
    assert not np.array_equal(own[1], free[1])
    # a wall box reaching through into the room behind labels only its own side
    wall = _prop(0, 2, 0.9, [0, 0, 1], [0.4, 4, 2])
    wall.space_id = 1
    xyz = np.array([[-0.1, 0, 1], [0.1, 0, 1]])
    assert label_arrays(xyz, _boxes([wall]), 0.02)[1].tolist() == [0, 0]
    assert label_arrays(xyz, _boxes([wall]), 0.02, space=np.array([1, 2]))[1].tolist() == [0, -1]


def test_first_classes_label_before_better_scored_boxes():
    # a table standing on the floor: its box reaches down into the floor's thin box
    props = [_prop(0, 1, 0.2, [0, 0, 0], [4, 4, 0.02]),  # floor, scored below the table
             _prop(1, 7, 0.9, [0, 0, 0.375], [1, 1, 0.75])]  # table, from the floor up
    pts = np.array([[0.1, 0.1, 0.005], [0.1, 0.1, 0.5], [1.5, 1.5, 0.0]])
    assert label_arrays(pts, _boxes(props), 0.02)[0].tolist() == [7, 7, 1]
    assert label_arrays(pts, _boxes(props), 0.02, first=(1,))[0].tolist() == [1, 7, 1]
    assert label_arrays(pts, _boxes(props), 0.02, first=(0,))[0].tolist() == [7, 7, 1]  # no ceiling here


def test_first_classes_against_the_brute_force_rule():
    differs = []
    for seed in range(6):
        pts, boxes, space = _random_case(seed, k=2 + seed % 3)
        for first in ((0, 1), (2,), tuple(range(12))):
            got = label_arrays(pts, boxes, 0.02, first=first)
            want = _reference(pts, boxes, 0.02, first=first)
            assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1]), (seed, first)
            got = label_arrays(pts, boxes, 0.02, space=space, first=first)
            want = _reference(pts, boxes, 0.02, space=space, first=first)
            assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1]), (seed, first)
        differs.append(not np.array_equal(label_arrays(pts, boxes, 0.02, first=(2,))[1], label_arrays(pts, boxes, 0.02)[1]))
    assert sum(differs) >= 3  # the rule changes labels where boxes of class 2 overlap better ones


def test_whole_boxes_label_the_cells_their_pattern_leaves_out():
    half = np.zeros((2, 2, 2), bool)
    half[:, :, 0] = True
    props = [_prop(0, 7, 0.9, [0, 0, 1], [2, 2, 2], occ=half)]
    pts = np.array([[0.5, 0.5, 0.5], [0.5, 0.5, 1.5]])
    assert label_arrays(pts, _boxes(props), 0.02)[0].tolist() == [7, 12]
    whole = _boxes(props, occupied=False)
    assert whole["occ"].shape == (1, 1, 1, 1) and whole["occ"].all()
    assert label_arrays(pts, whole, 0.02)[0].tolist() == [7, 7]
    pts, boxes, _ = _random_case(7, occupied=False)
    got, want = label_arrays(pts, boxes, 0.02), _reference(pts, boxes, 0.02)
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])


def test_label_rule_reads_the_settings():
    import dask
    import pytest

    from engine.outputs.labels import label_rule
    from tiles.errors import SettingsError

    assert label_rule() == {"margin": 0.02, "occupied": False, "first": ["ceiling", "floor"]}
    with dask.config.set({"buildingparser.detection.label-first": "floor", "buildingparser.detection.label-occupied": True}):
        assert label_rule() == {"margin": 0.02, "occupied": True, "first": ["floor"]}
    with dask.config.set({"buildingparser.detection.label-first": "floor,roof"}), pytest.raises(SettingsError, match="label-first"):
        label_rule()
