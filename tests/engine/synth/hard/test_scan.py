"""Difficulties in the points: each is measurable in the scan, and the ground truth stays exact."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
import shapely
from shapely.geometry import Polygon

from engine.synth import plan_building, scan_building
from engine.synth.faces import GLASS_DENSITY
from tiles.classes import CLASS_CODES


@pytest.fixture(scope="module")
def registered():
    b = plan_building(4, area_m2=300, density=400, hardness="registration")
    return b, scan_building(b)


def _face_offsets(cols, b, w, sid):
    """Signed offsets along the wall's normal of the points of ``sid``'s wall faces on the middle of wall ``w``."""
    inst = {e.id for e in b.spaces[sid].elements if e.cls == "wall"}
    P = np.c_[cols["x"], cols["y"]]
    rel = P - np.asarray(w.p0)
    along, off = rel @ w.direction, rel @ w.normal
    sel = np.isin(cols["gt_instance"], list(inst)) & (np.abs(off) < w.thickness / 2 + 0.1) \
        & (along > 0.3 * w.length) & (along < 0.7 * w.length) & (cols["gt_space"] == sid)
    return off[sel], P[sel]


def test_registration_offsets_are_measurable_between_two_rooms(registered):
    b, cols = registered
    best = None
    for w in b.walls:
        if w.kind != "interior" or w.length < 2.0 or w.openings:
            continue
        mid = np.r_[np.asarray(w.p0) + w.direction * w.length / 2, 1.0]
        shift = [b.spaces[s].registered(mid[None])[0, :2] - mid[:2] for s in (w.left, w.right)]
        expected = float((shift[0] - shift[1]) @ w.normal)  # left face moves by shift[0], right by shift[1]
        if best is None or abs(expected) > abs(best[1]):
            best = (w, expected)
    w, expected = best
    assert abs(expected) > 0.01
    left, _ = _face_offsets(cols, b, w, w.left)
    right, _ = _face_offsets(cols, b, w, w.right)
    assert len(left) > 50 and len(right) > 50
    gap = float(np.median(left) - np.median(right))
    assert gap - w.thickness == pytest.approx(expected, abs=0.012)
    # the ground truth knows it: the registration in world coordinates
    doc = b.ground_truth()
    reg = doc["spaces"][w.left]["registration"]
    assert set(reg) == {"offset", "yaw_deg", "pivot"} and abs(reg["yaw_deg"]) <= 0.4


def test_registered_boxes_keep_the_buildings_axes(registered):
    """A scan's registration error turns its points, not the walls that were built: every box keeps its element's
    yaw (S3DIS's boxes are in the building's frame) and grows to enclose its turned self (a long wall's box is
    thicker by its length times the sine of the turn)."""
    b, _ = registered
    gt = {e["id"]: e for e in b.ground_truth()["elements"]}
    grown = 0
    for s in b.spaces:
        turn = abs(s.registration_yaw)
        for e in s.elements:
            g = gt[e.id]
            assert g["yaw"] == pytest.approx(b.frame.angle(e.yaw), abs=1e-12)
            sx, sy = float(e.size[0]), float(e.size[1])
            assert g["size"][:2] == pytest.approx([math.cos(turn) * sx + math.sin(turn) * sy,
                                                   math.sin(turn) * sx + math.cos(turn) * sy], abs=1e-9)
            if e.cls == "wall" and max(sx, sy) > 3.0 and turn > math.radians(0.1):
                assert min(g["size"][:2]) > min(sx, sy) + 0.9 * max(sx, sy) * math.sin(turn)
                grown += 1
    assert grown > 0


def test_scan_positions_of_one_room_double_its_faces(registered):
    """Each scan position has its own residual error: a face seen from two of them is two parallel sheets."""
    b, cols = registered
    clean = scan_building(plan_building(4, area_m2=300, density=400))
    spreads = {}
    for name, c in (("hard", cols), ("clean", clean)):
        s = []
        for w in b.walls:
            if w.kind == "interior" and w.length > 3.0:
                for sid in (w.left, w.right):
                    if len(b.spaces[sid].scanners) > 1:
                        off, _ = _face_offsets(c, b, w, sid)
                        if len(off) > 100:
                            s.append(np.percentile(off, 95) - np.percentile(off, 5))
        spreads[name] = np.median(s)
    assert spreads["hard"] > spreads["clean"] + 0.003


def test_glass_has_far_fewer_points_per_square_metre_than_walls(hard, hard_scan):
    cols = hard_scan
    P = np.c_[cols["x"], cols["y"], cols["z"]]
    dens = {"glass": [], "solid": []}
    for w in hard.walls:
        if w.kind != "interior" or w.length < 2.0:
            continue
        for sid in (w.left, w.right):
            sp = hard.spaces[sid]
            if not sp.scanned:
                continue
            inst = [e.id for e in sp.elements if e.cls == "wall"]
            rel = P[:, :2] - np.asarray(w.p0)
            along, off = rel @ w.direction, (rel @ w.normal) * w.side_of(sid)
            z = P[:, 2] - sp.z0
            zlo, zhi = (w.glazing[0] + 0.15, w.glazing[1] - 0.15) if w.material == "glass" else (2.3, sp.z1 - sp.z0 - 0.15)
            if zhi - zlo < 0.3:
                continue
            near = np.isin(cols["gt_instance"], inst) & (np.abs(off - w.thickness / 2) < 0.03) & (z > zlo) & (z < zhi)
            near &= (along > 0.3) & (along < w.length - 0.3)
            for o in w.openings:
                near &= ~((along > o.s0 - 0.1) & (along < o.s1 + 0.1))
            if w.material == "glass":  # between the mullions
                pitch = 1.0 + 0.5 * ((w.id * 0.6180339887) % 1.0)
                near &= np.abs((along + pitch / 2) % pitch - pitch / 2) > 0.08
            area = (zhi - zlo) * (w.length - 0.6)
            dens["glass" if w.material == "glass" else "solid"].append(near.sum() / area / sp.density)
    assert dens["glass"] and dens["solid"]
    ratio = np.median(dens["glass"]) / np.median(dens["solid"])
    assert ratio < 2.5 * GLASS_DENSITY


def test_unscanned_rooms_have_no_points_but_their_walls_are_seen_from_outside(hard, hard_scan):
    cols = hard_scan
    for s in hard.spaces:
        if s.scanned:
            continue
        assert not np.any(cols["gt_space"] == s.id)
        outside = 0
        for wid in s.walls:
            w = hard.walls[wid]
            other = w.right if w.left == s.id else w.left
            if other < 0 or not hard.spaces[other].scanned:
                continue
            off, _ = _face_offsets(cols, hard, w, other)
            outside += len(off)
        assert outside > 100
    doc = hard.ground_truth({"spaces": {}, "elements": {}})
    assert all(d["points"] == 0 for d in doc["spaces"] if not d["scanned"])


def test_reflections_lie_outside_the_building(hard, hard_scan):
    cols = hard_scan
    ghost = cols["gt_space"] < 0
    assert ghost.sum() > 100
    assert np.all(cols["gt_instance"][ghost] == -1) and np.all(cols["gt_class"][ghost] == CLASS_CODES["clutter"])
    for f in range(len(hard.floors)):
        floor = shapely.union_all([Polygon(s.footprint) for s in hard.spaces if s.floor == f]
                                  + [Polygon(w.body()) for w in hard.walls if w.floor == f])
        lo, hi = hard.floors[f].z, hard.floors[f].ceiling_max
        sel = ghost & (cols["z"] >= lo) & (cols["z"] < hi)
        assert not np.any(shapely.contains_xy(floor, cols["x"][sel], cols["y"][sel]))
    assert np.all(cols["gt_space"] >= -1)


def test_flying_points_stay_in_their_space_off_the_surfaces(hard, hard_scan):
    cols = hard_scan
    flying = {e.id: e for e in hard.elements if e.info.get("kind") == "flying"}
    fly = np.isin(cols["gt_instance"], list(flying))
    assert 100 < fly.sum() < 0.05 * len(fly)
    for s in hard.spaces:
        sel = fly & (cols["gt_space"] == s.id)
        if sel.any():
            inside = shapely.contains_xy(Polygon(s.footprint).buffer(0.12), cols["x"][sel], cols["y"][sel])
            assert inside.mean() > 0.99  # (the scan's registration moves them a few cm)


def test_every_point_is_labelled_and_every_box_holds_its_points(hard, hard_scan, helpers):
    cols = hard_scan
    doc = hard.ground_truth()
    els = {e["id"]: e for e in doc["elements"]}
    P = helpers.xyz(cols)
    inst = cols["gt_instance"]
    assert np.all((cols["gt_class"] >= 0) & (cols["gt_class"] <= 12))
    ok = inst >= 0
    assert np.all(cols["gt_space"][ok] >= 0) and np.all(cols["gt_space"][~ok] == -1)
    order = np.argsort(inst, kind="stable")
    si = inst[order]
    cuts = np.flatnonzero(np.r_[True, si[1:] != si[:-1], True])
    for a, b in zip(cuts[:-1], cuts[1:]):
        if si[a] < 0:
            continue
        e = els[int(si[a])]
        sel = order[a:b]
        assert helpers.in_box(P[sel], e).all(), (e["class"], e.get("kind"))
        assert np.all(cols["gt_space"][sel] == e["space"]) and np.all(cols["gt_class"][sel] == e["class_code"])


def test_s3dis_layout_leaves_reflections_out(tmp_path):
    from engine.synth import generate

    r = generate(tmp_path / "s3dis", rooms=4, density=60, format="s3dis", hardness="artefacts")
    doc = json.loads((tmp_path / "s3dis" / "gt.json").read_text())
    rows = sum(sum(1 for _ in open(p)) for p in (tmp_path / "s3dis" / "Area_1").glob("*/*.txt"))
    assert rows == sum(d["points"] for d in doc["spaces"]) < r["points"]
    assert math.isfinite(r["points_per_second"])
