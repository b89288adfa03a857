"""Space update from detected walls (paper 4.2): merge where no wall lies in the connection area."""
from __future__ import annotations

import math

import numpy as np
import pytest

from engine.detection.proposals import SURE
from engine.spaces.alignment import Frame
from engine.spaces.document import Face, SpaceParse
from engine.spaces.update import UpdateSettings, face_coverage, merge_mapping, separated_pairs, update_spaces
from tiles.builder import StoreBuilder
from tiles.groundtruth import gt_dimensions
from tiles.schema import Dimension, Part, Source, coordinate_dimensions

H = 2.8
# three rooms along u (aligned metres): A and B are one hallway cut in two by a false divider at u = 4,
# C lies behind a real wall (void 8.0-8.2)
ROOMS = {0: (0.0, 4.0), 1: (4.0, 8.0), 2: (8.2, 12.0)}
TRUTH = {0: 0, 1: 0, 2: 1}


def _frame(yaw_deg):
    return Frame(math.radians(yaw_deg), (100.0, 50.0, 0.0))


def _wall(frame, u, v, du, dv, z0=0.0, dz=H):
    """A wall record from an aligned box centre/size (u, v) -> world centre and yaw."""
    c = frame.to_world(np.array([u, v]))
    return {"class": "wall", "class_code": 2, "center": [float(c[0]), float(c[1]), z0 + dz / 2],
            "size": [du, dv, dz], "yaw": frame.yaw}


def _face(pos, a, b, axis="u", divider=0.0):
    """A face; ``divider``: the score of a peak-gap-peak divider there (0: none)."""
    return {"axis": axis, "position": pos, "extent": [a, b], "z_range": [0.0, H], "segment": [[0, 0], [0, 0]],
            "divider": divider, "divider_kind": "peak-gap-peak" if divider else None, "score": divider or None}


def _doc(frame, ab_divider=0.0):
    spaces, cells = [], []
    faces = {(0, 1): [_face(4.0, 0.0, 4.0, divider=ab_divider)], (1, 2): [_face(8.1, 0.0, 4.0, divider=1.5)]}
    for sid, (u0, u1) in ROOMS.items():
        corners = frame.to_world(np.array([[u0, 0], [u1, 0], [u1, 4], [u0, 4], [u0, 0]]))
        nbs = [{"space": b if a == sid else a, "faces": f} for (a, b), f in faces.items() if sid in (a, b)]
        spaces.append({"id": sid, "floor": 0, "cells": [sid],
                       "footprint": {"type": "Polygon", "coordinates": [corners.tolist()]},
                       "area_m2": (u1 - u0) * 4, "z_range": [0.0, H], "point_count": 0, "tiles": [],
                       "neighbours": nbs})
        cells.append({"id": sid, "floor": 0, "box": [u0, 0.0, u1, 4.0], "point_count": 0, "space": sid})
    return {"version": 1, "frame": frame.to_json(), "grid": {"bin_width": 0.02, "z_bin": 0.02},
            "floors": [{"id": 0, "z_range": [0.0, H], "point_count": 0}], "cells": cells, "dividers": [],
            "spaces": spaces, "point_count": 0, "unassigned_points": 0, "stats": {}, "params": {}}


def _room_points(rng, u0, u1, n, ab, first):
    """What a scanner in the room sees: floor, ceiling, the long walls, and its end walls (u0/u1) as told."""
    area = (u1 - u0) * 4
    parts = [rng.uniform([u0, 0, 0], [u1, 4, 0], size=(int(n * 0.3), 3)),
             rng.uniform([u0, 0, H], [u1, 4, H], size=(int(n * 0.3), 3))]
    for v in (0.0, 4.0):
        parts.append(np.column_stack([rng.uniform(u0, u1, int(n * 0.1)), np.full(int(n * 0.1), v),
                                      rng.uniform(0, H, int(n * 0.1))]))
    for u, kind in ((u0, "wall" if first or u0 > 4.1 else ab), (u1, "wall" if u1 < 3.9 or u1 > 4.1 else ab)):
        m = int(n * 0.1)
        pts = np.column_stack([np.full(m, u), rng.uniform(0, 4, m), rng.uniform(0, H, m)])
        if kind == "archway":  # a wide opening, 2.1 m high: only the lintel and two short jambs are left
            pts = pts[(pts[:, 2] > 2.1) | (pts[:, 1] < 0.3) | (pts[:, 1] > 3.7)]
        elif kind in ("open", "glass"):  # nothing there (glass gives no points)
            pts = pts[:0]
        parts.append(pts)
    del area
    return np.concatenate(parts)


def _store(path, frame, n=3000, seed=0, ab="open", ab_divider=0.0):
    """Points in the three rooms (world), with gt_space and the over-split space_id, in several tiles.

    ``ab``: what lies between A and B at u = 4 ("open": one hallway; "archway"; "glass"; "wall").
    """
    rng = np.random.default_rng(seed)
    truth = dict(TRUTH) if ab in ("open", "archway") else {0: 0, 1: 1, 2: 2}
    pts, gt, sid = [], [], []
    for s, (u0, u1) in ROOMS.items():
        a = _room_points(rng, u0, u1, n, ab, s == 0)
        pts.append(frame.to_world(a))
        gt.append(np.full(len(a), truth[s]))
        sid.append(np.full(len(a), s))
    xyz, gt, sid = np.concatenate(pts), np.concatenate(gt), np.concatenate(sid)
    raw = np.round(xyz / 0.001).astype(np.int32)
    dims = coordinate_dimensions() + gt_dimensions()
    b = StoreBuilder.create(str(path), dimensions=dims, scale=[0.001] * 3, offset=[0.0, 0.0, 0.0], tile_size=5.0)
    cols = {"x": raw[:, 0], "y": raw[:, 1], "z": raw[:, 2], "gt_space": gt.astype(np.int32),
            "gt_class": np.zeros(len(gt), np.uint8), "gt_instance": np.full(len(gt), -1, np.int32)}
    summary = b.write_part(0, cols)
    store = b.finalize([summary], parts=[Part(0, 0, len(gt))], sources=[Source("mem", "test", len(gt))])
    store.add_dimensions([Dimension("space_id", "int32", "result", "space")])
    doc = _doc(frame, ab_divider)
    for t in store.tiles:
        pi = store.read(t, ["point_index"])["point_index"]
        store.write_array(t, "space_id", sid[pi].astype(np.int32))
        for s in doc["spaces"]:
            if np.any(sid[pi] == s["id"]):
                s["tiles"].append(t.name)
    for s in doc["spaces"]:
        s["point_count"] = int(np.count_nonzero(sid == s["id"]))
    store.set_doc("spaces", doc)
    return store, sid


def _building_walls(frame):
    return [_wall(frame, 8.1, 2.0, 0.2, 4.0),  # the real wall between B and C
            _wall(frame, 6.0, -0.1, 12.2, 0.2), _wall(frame, 6.0, 4.1, 12.2, 0.2),  # the hallway's sides
            _wall(frame, -0.1, 2.0, 0.2, 4.0), _wall(frame, 12.1, 2.0, 0.2, 4.0)]  # its ends


@pytest.mark.parametrize("yaw", [0.0, 30.0])
def test_update_merges_the_false_split_and_keeps_the_wall(tmp_path, client, yaw):
    frame = _frame(yaw)
    store, sid = _store(tmp_path / "s.zarr", frame)
    assert len(store.tiles) > 2
    parse = SpaceParse.load(store)
    new, mapping = update_spaces(store, parse, _building_walls(frame), client=client)
    assert mapping == {0: 0, 1: 0, 2: 1}
    rec = new.stats["space_update"]
    assert rec["ari_before"] < 0.9 and rec["ari_after"] == pytest.approx(1.0)
    assert rec["separated"] == 1 and rec["pairs"] == 2 and rec["points_relabelled"] == int(np.count_nonzero(sid >= 1))
    # every tile rewritten: the points of B now carry A's id, C's id moved down to 1
    for t in store.refresh().tiles:
        cols = store.read(t, ["space_id", "point_index"])
        expected = np.array([mapping[s] for s in sid[cols["point_index"]]])
        np.testing.assert_array_equal(cols["space_id"], expected)
    # the stored document is the merged parse
    back = SpaceParse.load(store)
    assert [s.id for s in back.spaces] == [0, 1]
    merged = back.space(0)
    assert merged.cells == [0, 1] and merged.point_count == int(np.count_nonzero(sid <= 1)) and merged.area_m2 == pytest.approx(32.0)
    assert [nb.space for nb in merged.neighbours] == [1]
    assert merged.neighbours[0].faces[0].position == pytest.approx(8.1)
    assert [c.space for c in back.cells] == [0, 0, 1]
    import shapely.geometry
    assert shapely.geometry.shape(merged.footprint).area == pytest.approx(32.0, rel=1e-3)


def test_paper_rule_merges_everything_without_walls_and_walls_everywhere_merge_nothing(tmp_path):
    frame = _frame(0.0)
    store, _ = _store(tmp_path / "s.zarr", frame, n=200)
    parse = SpaceParse.load(store)
    pairs = separated_pairs(parse, [], UpdateSettings())  # the paper's rule: no wall -> merge
    assert merge_mapping([0, 1, 2], pairs) == {0: 0, 1: 0, 2: 0}
    walls = _building_walls(frame) + [_wall(frame, 4.0, 2.0, 0.15, 4.0)]
    new, mapping = update_spaces(store, parse, walls, truth=None)
    assert mapping == {0: 0, 1: 1, 2: 2}
    assert new.stats["space_update"]["points_relabelled"] == 0 and "ari_before" not in new.stats["space_update"]


def test_no_wall_detected_keeps_a_parse_of_real_rooms(tmp_path):
    """Three rooms with walls between them: detection finds no wall at all, the parse stays as it is."""
    store, _ = _store(tmp_path / "s.zarr", _frame(20.0), n=2000, ab="wall")
    new, mapping = update_spaces(store, SpaceParse.load(store), [], truth="gt_space")
    assert mapping == {0: 0, 1: 1, 2: 2}
    rec = new.stats["space_update"]
    assert rec["merges"] == 0 and rec["ari_after"] == pytest.approx(rec["ari_before"]) == pytest.approx(1.0)
    assert rec["kept"]["not shown open"] == 2  # the walls leave a floor gap and a wall surface at both faces
    # the paper's rule alone (evidence off) merges the three rooms into one
    _, paper = update_spaces(store, SpaceParse.load(store), [], truth=None, params=UpdateSettings(evidence=False))
    assert set(paper.values()) == {0}


def test_glass_partition_with_a_strong_divider_stays_divided(tmp_path):
    """Glass between two rooms of one ceiling height: no points, no detected wall, floor and ceiling run
    through; the parse's divider there is strong evidence and wins."""
    store, _ = _store(tmp_path / "s.zarr", _frame(0.0), n=2000, ab="glass", ab_divider=5.0)
    _, mapping = update_spaces(store, SpaceParse.load(store), [], truth=None)
    assert mapping == {0: 0, 1: 1, 2: 2}


@pytest.mark.parametrize("yaw", [0.0, 35.0])
def test_wide_archway_is_merged(tmp_path, yaw):
    """A room cut in two at a wide archway (a lintel and short jambs only): the floor and ceiling run through
    at one height, no wall surface below the lintel -> merged; the wall beyond stays though detection found
    no wall at all (the paper's rule merged all three)."""
    frame = _frame(yaw)
    store, _ = _store(tmp_path / "s.zarr", frame, n=2000, ab="archway")
    new, mapping = update_spaces(store, SpaceParse.load(store), [], truth="gt_space")
    assert mapping == {0: 0, 1: 0, 2: 1}
    assert new.stats["space_update"]["ari_after"] == pytest.approx(1.0)


def test_faces_open_evidence():
    """The openness of one face from hand-made points: open floor, a wall surface, a height step."""
    from engine.spaces.openness import OpennessSettings, face_evidence

    rng = np.random.default_rng(3)
    face = Face("u", 0.0, [0.0, 3.0], [0.0, H], [[0, 0], [0, 0]], False)
    floor = np.column_stack([rng.uniform(-0.6, 0.6, 4000), rng.uniform(0, 3, 4000), np.zeros(4000)])
    ceil = floor + [0, 0, H]
    p = OpennessSettings()
    assert face_evidence(np.concatenate([floor, ceil]), face, p)["open"]
    wall = np.column_stack([np.full(3000, 0.05), rng.uniform(0, 3, 3000), rng.uniform(0, H, 3000)])
    assert not face_evidence(np.concatenate([floor, ceil, wall]), face, p)["open"]
    void = np.abs(floor[:, 0]) > 0.1
    assert not face_evidence(np.concatenate([floor[void], ceil]), face, p)["open"]
    high = ceil.copy()
    high[high[:, 0] > 0, 2] += 0.25
    assert face_evidence(np.concatenate([floor, high]), face, p)["reason"] == "height step"


def _one_face():
    return Face("u", 8.1, [0.0, 4.0], [0.0, H], [[0, 0], [0, 0]], False)


@pytest.mark.parametrize("yaw", [0.0, 55.0])
def test_face_coverage_rules(yaw):
    frame = _frame(yaw)
    p = UpdateSettings()
    face = _one_face()

    def cov(*walls):
        from engine.spaces.update import wall_boxes
        return face_coverage(face, wall_boxes(list(walls)), frame, p)

    assert cov(_wall(frame, 8.1, 2.0, 0.2, 4.0)) == pytest.approx(4.0)
    # two pieces with a door between them: their union, overlaps counted once
    assert cov(_wall(frame, 8.1, 0.7, 0.2, 1.4), _wall(frame, 8.1, 1.0, 0.2, 1.0), _wall(frame, 8.1, 3.2, 0.2, 1.6)) \
        == pytest.approx(1.5 + 1.6)
    assert cov(_wall(frame, 8.3, 2.0, 0.2, 4.0)) == pytest.approx(4.0)  # a little off: within thickness + 0.15
    assert cov(_wall(frame, 8.6, 2.0, 0.2, 4.0)) == 0.0  # the next wall over
    assert cov(_wall(frame, 8.1, 2.0, 4.0, 0.2)) == 0.0  # across the face, not along it
    assert cov(_wall(frame, 8.1, 2.0, 0.2, 4.0, dz=1.0)) == 0.0  # too low: a cabinet, not a wall
    assert cov(_wall(frame, 8.1, 5.0, 0.2, 4.0)) == pytest.approx(1.0)  # only its overlap with the face counts
    chair = dict(_wall(frame, 8.1, 2.0, 0.2, 4.0), class_code=8, **{"class": "chair"})
    assert cov(chair) == 0.0  # only walls
    # a wall added at its space's side because the space ends there (engine.detection.sides) is no evidence
    sure = dict(_wall(frame, 8.1, 2.0, 0.2, 4.0), extra={SURE: True})
    assert cov(sure) == 0.0


def test_parameters_are_checked():
    with pytest.raises(ValueError):
        UpdateSettings(coverage=0)
    with pytest.raises(ValueError):
        UpdateSettings(max_angle=120)
    assert UpdateSettings.from_config(coverage=0.8).coverage == 0.8
