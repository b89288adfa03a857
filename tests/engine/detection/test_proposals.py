"""Proposals survive the JSON round trip a resumed run relies on, and give the elements.json record."""
from __future__ import annotations

import json

import numpy as np

from engine.detection.proposals import Proposal, occupied_voxels, proposal_from_json, proposal_to_json


def _proposal(seed=0):
    rng = np.random.default_rng(seed)
    return Proposal(space_id=3, class_code=2, score=0.75, position=rng.random(3), size=rng.random(3),
                    occupancy=rng.random((4, 4, 4)) > 0.5, center=rng.random(3) * 10,
                    world_size=rng.random(3) + 0.1, yaw=0.3, element_id=7, extra={"atom": np.int64(4)})


def test_json_round_trip_is_lossless():
    p = _proposal()
    q = proposal_from_json(json.loads(json.dumps(proposal_to_json(p))))
    for f in ("position", "size", "center", "world_size"):
        np.testing.assert_array_equal(getattr(q, f), getattr(p, f))
    np.testing.assert_array_equal(q.occupancy, p.occupancy)
    assert (q.space_id, q.class_code, q.score, q.yaw, q.element_id) == (3, 2, 0.75, 0.3, 7)
    assert q.extra == {"atom": 4}


def test_element_record_has_the_contract_fields():
    rec = _proposal().element_record()
    assert set(rec) == {"element_id", "class", "class_code", "score", "space_id", "center", "size", "yaw", "voxels"}
    assert rec["class"] == "wall"


def test_occupied_voxels_tile_the_box():
    occ = np.zeros((2, 2, 2), bool)
    occ[0, 0, 0] = occ[1, 1, 1] = True
    vox = occupied_voxels(occ, np.array([2.0, 4.0, 6.0]))
    assert vox == [[-0.5, -1.0, -1.5, 1.0, 2.0, 3.0], [0.5, 1.0, 1.5, 1.0, 2.0, 3.0]]
