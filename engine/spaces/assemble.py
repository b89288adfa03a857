"""The parse put together from the labelled tiles: floors, cells, spaces with their footprints and faces."""
from __future__ import annotations

import math
from collections import defaultdict
from typing import Any

import numpy as np

from engine.spaces.alignment import Frame
from engine.spaces.document import Cell, Face, Floor, Neighbour, Space, SpaceParse
from engine.spaces.merging import Edge
from engine.spaces.refined_plan import RefinedPlan
from engine.spaces.settings import SpaceSettings
from engine.spaces.slicing import Box, FoundDivider


def assemble(store, p: SpaceSettings, frame: Frame, floors: list[tuple[int, int]], dividers: list[FoundDivider],
             boxes: list[Box], edges: list[Edge], labels: np.ndarray, labelled: list[dict[str, Any]],
             tiles: list[str], n_spaces: int, plan: RefinedPlan) -> SpaceParse:
    """The parse of a building from its cells (``boxes``), their spaces (``labels``) and the labelled tiles' counts.

    ``labelled``: the :func:`engine.spaces.labelling.label_tile` results of ``tiles``, in order.
    """
    from engine.spaces.footprints import clipped_footprint, union_footprint, union_geojson

    bw, zb = p.bin_width, p.z_bin
    oz = frame.origin[2]
    cell_counts = np.zeros(len(boxes), dtype=np.int64)
    space_counts = np.zeros(n_spaces, dtype=np.int64)
    zmin, zmax = np.full(n_spaces, np.inf), np.full(n_spaces, -np.inf)
    touched: dict[int, list[str]] = defaultdict(list)
    for name, r in zip(tiles, labelled):
        np.add.at(cell_counts, r["cells"], r["counts"])
        sp = labels[r["cells"]]
        ok = sp >= 0
        np.add.at(space_counts, sp[ok], r["counts"][ok])
        np.minimum.at(zmin, sp[ok], r["zmin"][ok])
        np.maximum.at(zmax, sp[ok], r["zmax"][ok])
        for s in np.unique(sp[ok]):
            touched[int(s)].append(name)
    floor_list = [Floor(i, [oz + a * zb, oz + b * zb], 0) for i, (a, b) in enumerate(floors)]
    cells = []
    for i, b in enumerate(boxes):
        cells.append(Cell(i, b.floor, [b.u0 * bw, b.v0 * bw, b.u1 * bw, b.v1 * bw], int(cell_counts[i]),
                          int(labels[i]), plan.cell_yaw[i]))
        floor_list[b.floor].point_count += int(cell_counts[i])
    faces = _faces(frame, edges, plan.sides, plan.edge_yaw, floor_list, bw)
    nb_of: dict[int, list[int]] = defaultdict(list)
    for a, o in sorted(faces):
        nb_of[a].append(o)
    members_of: dict[int, list[int]] = defaultdict(list)
    for i, lab in enumerate(labels.tolist()):
        if lab >= 0:
            members_of[lab].append(i)
    def footprint(rects: list[list[float]], sub: tuple[int, float] | None) -> tuple[dict[str, Any], float]:
        if sub is None:
            return union_footprint(rects, frame)
        k, yaw = sub
        return clipped_footprint(rects, Frame(yaw, frame.origin), [cells[i].box for i in plan.clip[k]], frame)

    spaces = []
    for s in range(n_spaces):
        members = members_of[s]
        rects = [cells[i].box for i in members]
        if s in plan.joined:  # spaces joined after refinement: the union of their footprints
            parts = [footprint([cells[i].box for i in members if plan.before[i] == old], plan.sub_before.get(old))
                     for old in plan.joined[s]]
            fp, area = union_geojson([f for f, _ in parts])
        else:
            fp, area = footprint(rects, plan.sub_of.get(s))
        nbs = [Neighbour(o, faces[(s, o)]) for o in nb_of.get(s, [])]
        zr = ([float(zmin[s]), float(zmax[s])] if np.isfinite(zmin[s])
              else list(floor_list[boxes[members[0]].floor].z_range))
        spaces.append(Space(s, boxes[members[0]].floor, members, fp, area, zr, int(space_counts[s]),
                            touched.get(s, []), nbs))
    return SpaceParse(frame, bw, zb, floor_list, cells, dividers, spaces, point_count=int(store.meta.point_count),
                      unassigned_points=int(sum(r["unassigned"] for r in labelled)), params=p.to_dict())


def _faces(frame: Frame, edges: list[Edge], sides: np.ndarray, edge_yaw: list[float | None], floors: list[Floor],
           bw: float) -> dict[tuple[int, int], list[Face]]:
    """Shared faces between different spaces (both directions), contiguous pieces of one frame joined.

    ``sides[e]``: the space on each side of edge ``e``; ``edge_yaw[e]``: its frame (None: the building's).
    """
    pieces: dict[tuple[int, int], list[tuple]] = defaultdict(list)
    for e, (sa, sb), yaw in zip(edges, sides.tolist(), edge_yaw):
        if sa < 0 or sb < 0 or sa == sb:
            continue
        kind = e.divider.get("kind") if e.divider else None
        score = float(e.divider.get("score", 0.0)) if e.divider else None
        key = (min(sa, sb), max(sa, sb))
        pieces[key].append((math.nan if yaw is None else float(yaw), e.axis, e.position, e.overlap[0], e.overlap[1],
                            e.divider is not None, kind, score, e.floor))
    out: dict[tuple[int, int], list[Face]] = defaultdict(list)
    for key, items in pieces.items():
        items.sort(key=lambda x: (not math.isnan(x[0]), 0.0 if math.isnan(x[0]) else x[0], x[1], x[2], x[5], x[3]))
        joined: list[list] = []
        for it in items:
            last = joined[-1] if joined else None
            same_frame = (math.isnan(last[0]) and math.isnan(it[0])) or last[0] == it[0] if last else False
            if last and same_frame and last[1:3] == list(it[1:3]) and last[5] == it[5] and last[4] == it[3]:
                last[4] = it[4]
                if it[7] is not None:
                    last[7] = max(last[7] or 0.0, it[7])
            else:
                joined.append(list(it))
        faces = []
        for yaw, axis, pos, o0, o1, div, kind, score, floor in joined:
            fr = frame if math.isnan(yaw) else Frame(yaw, frame.origin)
            a = pos * bw
            ends = [[a, o0 * bw], [a, o1 * bw]] if axis == 0 else [[o0 * bw, a], [o1 * bw, a]]
            seg = fr.to_world(np.array(ends))
            faces.append(Face("u" if axis == 0 else "v", a, [o0 * bw, o1 * bw], list(floors[floor].z_range),
                              [[float(v) for v in seg[0]], [float(v) for v in seg[1]]], bool(div), kind, score,
                              None if math.isnan(yaw) else yaw))
        out[key] = faces
        out[(key[1], key[0])] = faces
    return out
