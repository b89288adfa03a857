"""One set of elements per space after the space update merged spaces (issue 23)."""
from __future__ import annotations

import math

import numpy as np

from engine.detection.proposals import Proposal
from engine.outputs.reconcile import reconcile_elements
from engine.spaces.document import SpaceParse
from tests.engine.spaces.test_update import H, _doc, _frame
from tiles.classes import CLASS_CODES

K = 4


def _el(eid, space, cls, frame, u, v, z, du, dv, dz, score=1.0):
    c = frame.to_world(np.array([u, v]))
    return Proposal(space, CLASS_CODES[cls], score, np.zeros(3), np.ones(3), np.ones((K, K, K), bool),
                    np.array([c[0], c[1], z]), np.array([du, dv, dz]), frame.yaw, element_id=eid)


def _elements(frame):
    """Rooms A (u 0-4) and B (u 4-8) of one hallway, each with its floor and ceiling; a chair straddling the
    old seam found from both sides; a wall found on the seam; the real wall B|C; C's own floor and ceiling."""
    return [_el(0, 0, "floor", frame, 2, 2, 0.0, 4, 4, 0.02), _el(1, 0, "ceiling", frame, 2, 2, H, 4, 4, 0.02),
            _el(2, 1, "floor", frame, 6, 2, 0.01, 4, 4, 0.02), _el(3, 1, "ceiling", frame, 6, 2, H, 4, 4, 0.02),
            _el(4, 0, "chair", frame, 4.0, 1.0, 0.45, 0.5, 0.5, 0.9, score=0.8),
            _el(5, 1, "chair", frame, 4.05, 1.0, 0.45, 0.5, 0.5, 0.9, score=0.6),
            _el(6, 1, "wall", frame, 4.02, 2.0, H / 2, 0.1, 2.5, H),  # on the removed divider
            _el(7, 1, "wall", frame, 8.0, 2.0, H / 2, 0.1, 4.0, H),  # B|C: stays
            _el(8, 2, "floor", frame, 10, 2, 0.0, 3.8, 4, 0.02), _el(9, 2, "ceiling", frame, 10, 2, H, 3.8, 4, 0.02),
            _el(10, 0, "chair", frame, 1.0, 3.0, 0.45, 0.5, 0.5, 0.9)]


def test_after_a_merge_one_floor_and_one_ceiling_per_space():
    frame = _frame(30.0)
    parsed = SpaceParse.from_doc(_doc(frame))
    space_of = {0: 0, 1: 0, 2: 1}
    els = _elements(frame)
    origin = {e.element_id: e.space_id for e in els}
    for e in els:
        e.space_id = space_of[e.space_id]
    out, rep = reconcile_elements(els, parsed, space_of, origin)
    for sid in (0, 1):
        mine = [e for e in out if e.space_id == sid]
        assert sum(e.class_code == CLASS_CODES["floor"] for e in mine) == 1
        assert sum(e.class_code == CLASS_CODES["ceiling"] for e in mine) == 1
    floor = next(e for e in out if e.space_id == 0 and e.class_code == CLASS_CODES["floor"])
    assert floor.element_id == 0 and floor.extra["reconciled"] == {"from": [0, 2], "reason": "one floor per space"}
    assert np.allclose(sorted(floor.world_size[:2]), [4, 8], atol=1e-6)  # the union of the two floors
    assert math.isclose(floor.yaw, frame.yaw)
    assert rep["floors_joined"] == 1 and rep["ceilings_joined"] == 1
    assert rep["duplicates_suppressed"] == 1 and rep["seam_walls_dropped"] == 1
    assert rep["removed"] == [2, 3, 5, 6]
    assert {e.element_id for e in out} == {0, 1, 4, 7, 8, 9, 10}
    # the unmerged space is untouched, element for element
    assert [e for e in out if e.space_id == 1] == [els[8], els[9]]


def test_floors_at_distinct_heights_stay_apart_with_the_reason():
    frame = _frame(0.0)
    parsed = SpaceParse.from_doc(_doc(frame))
    space_of = {0: 0, 1: 0, 2: 1}
    els = _elements(frame)[:4]
    els[2].center[2] = 0.45  # B's floor is a raised platform
    origin = {e.element_id: e.space_id for e in els}
    for e in els:
        e.space_id = space_of[e.space_id]
    out, rep = reconcile_elements(els, parsed, space_of, origin)
    assert sum(e.class_code == CLASS_CODES["floor"] for e in out) == 2
    assert rep["distinct_heights"] == [{"space_id": 0, "class": "floor", "heights": [0.0, 0.45]}]


def test_nothing_merged_changes_nothing():
    frame = _frame(0.0)
    parsed = SpaceParse.from_doc(_doc(frame))
    els = _elements(frame)
    out, rep = reconcile_elements(els, parsed, {0: 0, 1: 1, 2: 2}, {e.element_id: e.space_id for e in els})
    assert out == els and rep["removed"] == [] and rep["merged_spaces"] == 0


def test_elements_json_records_the_reconciliation(tmp_path):
    from engine.outputs.labels import read_elements_json, write_elements_json

    frame = _frame(0.0)
    parsed = SpaceParse.from_doc(_doc(frame))
    space_of = {0: 0, 1: 0, 2: 1}
    els = _elements(frame)
    origin = {e.element_id: e.space_id for e in els}
    for e in els:
        e.space_id = space_of[e.space_id]
    out, _ = reconcile_elements(els, parsed, space_of, origin)
    recs = {r["element_id"]: r for r in read_elements_json(write_elements_json(out, tmp_path / "elements.json"))}
    assert recs[0]["reconciled"] == {"from": [0, 2], "reason": "one floor per space"}
    assert "reconciled" not in recs[8] and 2 not in recs
