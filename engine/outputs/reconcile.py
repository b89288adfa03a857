"""One set of elements per space after the space update merged spaces (issue 23).

Detection runs per parsed space, so a final space made of several parsed ones
carries one floor and one ceiling per old piece, duplicates of the elements
that straddled the old seam, and walls found on the removed divider.  Here,
per final space made of several parsed spaces (``space_of``: parsed id ->
final id):

* **floors and ceilings**: the space's floors (ceilings) are grouped by height
  (``height_tol`` metres between box centres); each group becomes one element
  whose box is the union of the group's boxes in the building's aligned frame
  (full occupancy, the best score, the smallest element id).  Groups at
  distinct heights stay distinct elements and the reason is recorded
  (``extra["reconciled"]``: a floor or ceiling step inside the space);
* **duplicates**: elements of one class from different parsed pieces whose
  world boxes overlap by an IoU of at least ``nms_iou`` (axis-aligned bounds)
  are suppressed but the best scoring one (NMS over the merged space);
* **walls on the removed divider**: walls of the merged space running along
  a face between two of its pieces (within ``seam_distance`` metres and
  ``seam_angle`` degrees, at least half of the wall's length on the face) go.

The report counts each kind and lists the element ids removed.
"""
from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from engine.detection.proposals import Proposal
from engine.spaces.alignment import Frame
from engine.spaces.document import Face, SpaceParse
from tiles.classes import CLASS_CODES

CEILING, FLOOR, WALL = CLASS_CODES["ceiling"], CLASS_CODES["floor"], CLASS_CODES["wall"]


def _corners(e: Proposal) -> np.ndarray:
    """The four plan corners ``(4, 2)`` (world) of an element's box."""
    c, s = math.cos(e.yaw), math.sin(e.yaw)
    hx, hy = float(e.world_size[0]) / 2, float(e.world_size[1]) / 2
    local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    rot = np.array([[c, -s], [s, c]])
    return local @ rot.T + np.asarray(e.center[:2])


def _bounds(e: Proposal) -> np.ndarray:
    """World axis-aligned bounds ``[x0, y0, z0, x1, y1, z1]``."""
    xy = _corners(e)
    z0, z1 = float(e.center[2] - e.world_size[2] / 2), float(e.center[2] + e.world_size[2] / 2)
    return np.array([*xy.min(0), z0, *xy.max(0), z1])


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    inter = np.prod(np.clip(np.minimum(a[3:], b[3:]) - np.maximum(a[:3], b[:3]), 0, None))
    va, vb = np.prod(a[3:] - a[:3]), np.prod(b[3:] - b[:3])
    return float(inter / max(va + vb - inter, 1e-12))


def _union_slab(group: list[Proposal], frame: Frame, reason: str) -> Proposal:
    """One floor or ceiling for ``group``: the union of their boxes in the aligned frame."""
    al = np.concatenate([frame.to_aligned(_corners(e)) for e in group])
    lo, hi = al.min(0), al.max(0)
    z0 = min(float(e.center[2] - e.world_size[2] / 2) for e in group)
    z1 = max(float(e.center[2] + e.world_size[2] / 2) for e in group)
    centre = frame.to_world((lo + hi) / 2)
    best = max(group, key=lambda e: (e.score, -e.element_id))
    k = np.asarray(best.occupancy).shape[0] if np.asarray(best.occupancy).ndim == 3 else 1
    extra = dict(best.extra)
    extra["reconciled"] = {"from": sorted(int(e.element_id) for e in group), "reason": reason}
    return replace(best, center=np.array([centre[0], centre[1], (z0 + z1) / 2]),
                   world_size=np.array([hi[0] - lo[0], hi[1] - lo[1], z1 - z0]), yaw=float(frame.yaw),
                   occupancy=np.ones((k, k, k), bool), element_id=min(int(e.element_id) for e in group),
                   extra=extra)


def _seam_faces(parsed: SpaceParse, space_of: dict[int, int]) -> dict[int, list[Face]]:
    """Per final space, the faces between two of its parsed pieces (the removed dividers)."""
    out: dict[int, list[Face]] = defaultdict(list)
    for s in parsed.spaces:
        for nb in s.neighbours:
            if nb.space > s.id and space_of.get(s.id, s.id) == space_of.get(nb.space, nb.space):
                out[space_of.get(s.id, s.id)].extend(nb.faces)
    return out


def _on_seam(wall: Proposal, faces: list[Face], frame: Frame, distance: float, angle: float) -> bool:
    """Whether at least half of ``wall``'s length runs along one of ``faces``."""
    long_x = wall.world_size[0] >= wall.world_size[1]
    length = float(max(wall.world_size[0], wall.world_size[1]))
    for f in faces:
        fr = frame if f.yaw is None else Frame(float(f.yaw), frame.origin)
        k = 0 if f.axis == "u" else 1
        c = fr.to_aligned(np.asarray(wall.center[:2], dtype=float))
        wall_dir = wall.yaw - fr.yaw + (0.0 if long_x else math.pi / 2)
        face_dir = math.pi / 2 if k == 0 else 0.0
        diff = abs((wall_dir - face_dir + math.pi / 2) % math.pi - math.pi / 2)
        if diff > math.radians(angle) or abs(c[k] - float(f.position)) > distance:
            continue
        a0, a1 = c[1 - k] - length / 2, c[1 - k] + length / 2
        if min(a1, f.extent[1]) - max(a0, f.extent[0]) >= 0.5 * length:
            return True
    return False


def reconcile_elements(elements: Sequence[Proposal], parsed: SpaceParse, space_of: dict[int, int],
                       origin: dict[int, int], *, height_tol: float = 0.15, nms_iou: float = 0.5,
                       seam_distance: float = 0.15, seam_angle: float = 20.0
                       ) -> tuple[list[Proposal], dict[str, Any]]:
    """One set of elements per merged space (see the module docstring).

    ``elements`` carry their final space ids; ``origin[element_id]`` is each element's parsed space id and
    ``space_of`` maps parsed to final ids.  Returns the elements kept (input order, merged slabs in place of
    their group's first member) and a report.
    """
    pieces: dict[int, set[int]] = defaultdict(set)
    for old, new in space_of.items():
        pieces[new].add(old)
    merged = {s for s, p in pieces.items() if len(p) > 1}
    seams = _seam_faces(parsed, space_of)
    report: dict[str, Any] = {"merged_spaces": len(merged), "floors_joined": 0, "ceilings_joined": 0,
                              "distinct_heights": [], "duplicates_suppressed": 0, "seam_walls_dropped": 0,
                              "removed": []}
    drop: set[int] = set()
    replace_by: dict[int, Proposal] = {}
    by_space: dict[int, list[Proposal]] = defaultdict(list)
    for e in elements:
        if e.space_id in merged:
            by_space[int(e.space_id)].append(e)
    for sid in sorted(by_space):
        els = by_space[sid]
        for code, name in ((FLOOR, "floor"), (CEILING, "ceiling")):
            slabs = sorted((e for e in els if e.class_code == code), key=lambda e: float(e.center[2]))
            groups: list[list[Proposal]] = []
            for e in slabs:
                if groups and float(e.center[2]) - float(groups[-1][-1].center[2]) <= height_tol:
                    groups[-1].append(e)
                else:
                    groups.append([e])
            if len(groups) > 1:
                report["distinct_heights"].append({"space_id": sid, "class": name, "heights": [
                    round(float(np.mean([float(e.center[2]) for e in g])), 3) for g in groups]})
            for g in groups:
                if len(g) < 2:
                    continue
                why = (f"one {name} per space" if len(groups) == 1 else
                       f"one {name} per height: the space has {len(groups)} {name} heights more than "
                       f"{height_tol} m apart")
                replace_by[id(g[0])] = _union_slab(g, parsed.frame, why)
                drop.update(id(e) for e in g[1:])
                report[f"{name}s_joined"] += len(g) - 1
        for e in els:
            if e.class_code == WALL and _on_seam(e, seams.get(sid, []), parsed.frame, seam_distance, seam_angle):
                drop.add(id(e))
                report["seam_walls_dropped"] += 1
        rest = sorted((e for e in els if e.class_code not in (FLOOR, CEILING) and id(e) not in drop),
                      key=lambda e: (-e.score, e.element_id))
        kept: list[Proposal] = []
        for e in rest:
            b = _bounds(e)
            if any(k.class_code == e.class_code and origin.get(k.element_id) != origin.get(e.element_id)
                   and _iou(b, _bounds(k)) >= nms_iou for k in kept):
                drop.add(id(e))
                report["duplicates_suppressed"] += 1
            else:
                kept.append(e)
    out = []
    for e in elements:
        if id(e) in drop:
            report["removed"].append(int(e.element_id))
        else:
            out.append(replace_by.get(id(e), e))
    report["removed"].sort()
    return out, report
