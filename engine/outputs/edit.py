"""Space manipulation (paper Sec. 1): merge spaces by removing the wall between them, or split a space by a line.

An edit reads a finished run's folder (``spaces.geojson``, ``elements.json``,
``points.laz``, ``metrics.json``) and writes the edited run into another folder
(never the original, unless asked): the spaces layer (``spaces.geojson`` and ``spaces.gpkg``), the
elements, a new ``points.laz`` variant (and ``points.copc.laz`` when the run has one: the same octree, its
points edited alike, :mod:`tiles.copc_rewrite`), the statistics, the floor plan, ``building.ifc`` and the
report, with an ``edit`` record in ``metrics.json``.

Merge ``A B ...`` (spaces of one storey, each touching another of them):

* the spaces become one, with the smallest id; its footprint is the union of
  theirs;
* the walls between them are removed: a wall of one of them whose footprint
  runs along the shared boundary (``SEAM_DISTANCE`` of it over at least
  ``SEAM_SHARE`` of its length), and the doors and windows set in such a wall;
  their points are removed from ``points.laz`` (they no longer exist);
* the floors and ceilings of the merged spaces at one height (within
  ``SLAB_TOLERANCE``) become one element, as the space update's
  reconciliation does (``reconciled`` says from which).

Split ``A`` by a line: the space's footprint is cut by the line (a segment
extended across the space); the part on the line's left keeps the id, the
other gets a new one; points and elements go by the side their position lies
on.

Points are streamed through in chunks (``CHUNK_POINTS``) in their order; the
LAS header, VLRs and every dimension are kept.
"""
from __future__ import annotations

import json
import os
import shutil
from collections.abc import Sequence
from typing import Any

import numpy as np

from engine.metrics.boxes import long_axis
from engine.outputs.runfolder import read_run_outputs
from tiles.errors import UserError

SEAM_DISTANCE = 0.30
SEAM_SHARE = 0.5
SLAB_TOLERANCE = 0.10
CHUNK_POINTS = 2_000_000
#: Elements set in a wall: removed with it.
IN_WALL = ("door", "window")


def _load(run: str) -> tuple[dict[str, Any], list[dict[str, Any]], dict[str, Any]]:
    layer, elements = read_run_outputs(run, need=("points.laz",))
    metrics = {}
    if os.path.isfile(os.path.join(run, "metrics.json")):
        with open(os.path.join(run, "metrics.json")) as f:
            metrics = json.load(f)
    return layer, elements, metrics


def _features(layer: dict[str, Any]) -> dict[int, dict[str, Any]]:
    return {int(f["properties"]["id"]): f for f in layer["features"]}


def wall_on_seam(wall: dict[str, Any], seam, distance: float = SEAM_DISTANCE, share: float = SEAM_SHARE) -> bool:
    """True when a wall's long axis runs along ``seam`` (a shapely line): within ``distance`` of it over at
    least ``share`` of the wall's length."""
    line = _wall_line(wall)
    if line.length == 0 or seam.is_empty:
        return False
    return line.intersection(seam.buffer(distance)).length >= share * line.length


def _seam(features: dict[int, dict[str, Any]], ids: Sequence[int]):
    """The boundary shared by the spaces ``ids`` (pairwise boundary intersections, widened by a hair)."""
    from shapely.geometry import shape
    from shapely.ops import unary_union

    polys = {i: shape(features[i]["geometry"]) for i in ids}
    pieces = []
    for k, a in enumerate(ids):
        for b in ids[k + 1:]:
            pieces.append(polys[a].buffer(SEAM_DISTANCE / 2).intersection(polys[b].buffer(SEAM_DISTANCE / 2)))
    return unary_union(pieces).boundary if pieces else None, polys


def _merge_slabs(elements: list[dict[str, Any]], new_id: int) -> list[dict[str, Any]]:
    """One floor and one ceiling per height among the merged space's slabs; returns the elements to keep."""
    out, slabs = [], {"floor": [], "ceiling": []}
    for e in elements:
        (slabs[e["class"]] if e["class"] in slabs and e["space_id"] == new_id else out).append(e)
    for group in slabs.values():
        group.sort(key=lambda e: e["center"][2])
        while group:
            z = group[0]["center"][2]
            same = [e for e in group if abs(e["center"][2] - z) <= SLAB_TOLERANCE]
            group = [e for e in group if e not in same]
            if len(same) == 1:
                out.append(same[0])
                continue
            lo = np.min([np.asarray(e["center"]) - np.asarray(e["size"]) / 2 for e in same], axis=0)
            hi = np.max([np.asarray(e["center"]) + np.asarray(e["size"]) / 2 for e in same], axis=0)
            first = min(same, key=lambda e: e["element_id"])
            out.append(dict(first, center=((lo + hi) / 2).tolist(), size=(hi - lo).tolist(), yaw=0.0,
                            score=max(e["score"] for e in same),
                            reconciled={"from": sorted(e["element_id"] for e in same), "reason": "edit merge"}))
    return sorted(out, key=lambda e: e["element_id"])


def plan_merge(layer: dict[str, Any], elements: list[dict[str, Any]], ids: Sequence[int]
               ) -> tuple[dict[str, Any], list[dict[str, Any]], dict[str, Any]]:
    """The merged spaces layer, the elements after the merge, and what was done (``removed`` element ids...)."""
    from shapely.geometry import mapping
    from shapely.ops import unary_union

    features = _features(layer)
    ids = sorted({int(i) for i in ids})
    missing = [i for i in ids if i not in features]
    if len(ids) < 2 or missing:
        raise UserError(None, f"--merge needs two or more existing spaces (no space {missing})" if missing
                        else "--merge needs two or more spaces")
    floors = {int(features[i]["properties"].get("floor", 0)) for i in ids}
    if len(floors) > 1:
        raise UserError(None, f"spaces {ids} lie on different storeys ({sorted(floors)}): they cannot merge")
    seam, polys = _seam(features, ids)
    if seam is None or seam.is_empty:
        raise UserError(None, f"spaces {ids} do not touch: nothing to merge across")
    new_id = ids[0]
    walls = [e for e in elements if e["class"] == "wall" and e["space_id"] in ids and wall_on_seam(e, seam)]
    removed = {e["element_id"] for e in walls}
    from shapely.geometry import Point

    lines = [_wall_line(w) for w in walls]
    holes = [e for e in elements if e["class"] in IN_WALL and e["space_id"] in ids
             and any(line.distance(Point(e["center"][:2])) <= SEAM_DISTANCE for line in lines)]
    removed |= {e["element_id"] for e in holes}
    kept = [dict(e, space_id=new_id) if e["space_id"] in ids else e for e in elements if e["element_id"] not in removed]
    kept = _merge_slabs(kept, new_id)
    merged = dict(features[new_id], geometry=mapping(unary_union([polys[i] for i in ids]).buffer(0)))
    p = dict(merged["properties"])
    p["area_m2"] = round(float(sum(features[i]["properties"].get("area_m2", 0.0) for i in ids)), 3)
    p["point_count"] = int(sum(features[i]["properties"].get("point_count", 0) for i in ids))
    p["z_min"] = min(float(features[i]["properties"].get("z_min", 0.0)) for i in ids)
    p["z_max"] = max(float(features[i]["properties"].get("z_max", 0.0)) for i in ids)
    merged["properties"] = p
    out = dict(layer, features=[merged if int(f["properties"]["id"]) == new_id else f for f in layer["features"]
                                if int(f["properties"]["id"]) not in ids[1:]])
    return out, kept, {"merge": ids, "space": new_id, "removed_elements": sorted(removed),
                       "space_map": {i: new_id for i in ids[1:]}}


def _wall_line(wall: dict[str, Any]):
    """A wall's long horizontal axis as a shapely segment."""
    from shapely.geometry import LineString

    axis, length = long_axis(wall["size"], float(wall["yaw"]))
    c = np.asarray(wall["center"][:2], dtype=float)
    return LineString([c - axis * length / 2, c + axis * length / 2])


def plan_split(layer: dict[str, Any], elements: list[dict[str, Any]], space: int, line: Sequence[float]
               ) -> tuple[dict[str, Any], list[dict[str, Any]], dict[str, Any]]:
    """The layer and elements after cutting ``space`` by the line through ``(x0, y0, x1, y1)``."""
    from shapely.geometry import LineString, mapping, shape
    from shapely.ops import split

    features = _features(layer)
    if int(space) not in features:
        raise UserError(None, f"--split: no space {space}")
    poly = shape(features[int(space)]["geometry"])
    a, b = np.asarray(line[:2], float), np.asarray(line[2:4], float)
    if np.allclose(a, b):
        raise UserError(None, "--line needs two different points")
    d = (b - a) / np.linalg.norm(b - a)
    reach = 2 * (poly.length + np.linalg.norm(a - np.asarray(poly.centroid.coords[0])))
    parts = list(split(poly, LineString([a - d * reach, a + d * reach])).geoms)
    if len(parts) < 2:
        raise UserError(None, f"the line does not cut space {space}")
    left = [q for q in parts if _side(np.asarray(q.representative_point().coords[0]), a, d) > 0]
    right = [q for q in parts if q not in left]
    new_id = max(features) + 1
    feats = []
    for f in layer["features"]:
        if int(f["properties"]["id"]) != int(space):
            feats.append(f)
            continue
        for sid, group in ((int(space), left), (new_id, right)):
            from shapely.ops import unary_union

            g = unary_union(group)
            props = dict(f["properties"], id=sid, area_m2=round(float(g.area), 3))
            feats.append(dict(f, geometry=mapping(g), properties=props))
    moved = [dict(e, space_id=new_id) if e["space_id"] == int(space)
             and _side(np.asarray(e["center"][:2], float), a, d) <= 0 else e for e in elements]
    return dict(layer, features=feats), moved, {"split": int(space), "new_space": new_id,
                                                "line": [float(v) for v in line[:4]]}


def _side(p: np.ndarray, a: np.ndarray, d: np.ndarray) -> float:
    """> 0 left of the directed line through ``a`` along ``d``."""
    return float(d[0] * (p[1] - a[1]) - d[1] * (p[0] - a[0]))


def edit_points(points, record: dict[str, Any]):
    """One chunk of a run's points (a laspy point record) with the edit applied to ``space_id`` and the points of
    removed elements dropped."""
    removed = np.asarray(record.get("removed_elements", []), dtype=np.int64)
    space = np.asarray(points["space_id"]).copy()
    for k, v in record.get("space_map", {}).items():
        space[np.asarray(points["space_id"]) == int(k)] = int(v)
    if "split" in record:
        a = np.asarray(record["line"][:2])
        d = np.asarray(record["line"][2:4]) - a
        d = d / np.linalg.norm(d)
        right = (d[0] * (np.asarray(points.y) - a[1]) - d[1] * (np.asarray(points.x) - a[0])) <= 0
        space[(space == record["split"]) & right] = record["new_space"]
    points["space_id"] = space
    if not len(removed):
        return points
    keep = ~np.isin(np.asarray(points["element_id"]), removed)
    return points if keep.all() else points[keep]


def rewrite_points(src: str, dst: str, record: dict[str, Any]) -> dict[str, int]:
    """Stream ``points.laz`` into ``dst`` with the edit applied (:func:`edit_points`)."""
    import laspy

    counts = {"points_in": 0, "points_out": 0, "points_removed": 0}
    tmp = dst + ".tmp.laz"
    with laspy.open(src) as reader, laspy.open(tmp, mode="w", header=reader.header,
                                              do_compress=dst.endswith(".laz")) as writer:
        for chunk in reader.chunk_iterator(CHUNK_POINTS):
            out = edit_points(chunk, record)
            counts["points_in"] += len(chunk)
            counts["points_out"] += len(out)
            writer.write_points(out)
    counts["points_removed"] = counts["points_in"] - counts["points_out"]
    os.replace(tmp, dst)
    return counts


def _edited_metrics(metrics: dict[str, Any], record: dict[str, Any], run: str, spaces: int) -> dict[str, Any]:
    """``metrics.json`` of the edited run: the edit recorded; the scores of the run it came from kept under
    ``edit.before`` (they describe the spaces and elements before the edit)."""
    before = {k: metrics.get(k) for k in ("spaces", "detection") if metrics.get(k) is not None}
    out = {k: v for k, v in metrics.items() if k != "detection"}
    out["spaces"] = {"count": spaces}
    out["edit"] = {"from": run, **{k: v for k, v in record.items() if k != "space_map"}, "before": before}
    return out


def edit_run(run: str, out: str, *, merge: Sequence[int] | None = None, split: int | None = None,
             line: Sequence[float] | None = None, in_place: bool = False) -> dict[str, Any]:
    """Apply one edit to the run folder ``run`` and write the edited run to ``out``; returns the edit record."""
    from engine.outputs.daylight import layer_with_figures
    from engine.outputs.geojson import write_spaces_gpkg
    from engine.outputs.plan import draw_plan
    from engine.outputs.report import write_report
    from tiles.copc_rewrite import rewrite_copc
    from tiles.crs import parse_crs

    run, out = os.path.abspath(run), os.path.abspath(out)
    if (merge is None) == (split is None):
        raise UserError(None, "give one edit: --merge A B ... or --split A --line X0 Y0 X1 Y1")
    if out == run and not in_place:
        raise UserError(out, "is the run folder itself: the edit would overwrite it (add --in-place to allow)")
    if out != run and os.path.exists(out) and os.listdir(out):
        raise UserError(out, "exists and is not empty: choose a new folder for the edited run")
    layer, elements, metrics = _load(run)
    if merge is not None:
        layer, elements, record = plan_merge(layer, elements, merge)
    else:
        if line is None or len(line) != 4:
            raise UserError(None, "--split needs --line X0 Y0 X1 Y1")
        layer, elements, record = plan_split(layer, elements, int(split), line)
    staging = out + ".edit-tmp"
    shutil.rmtree(staging, ignore_errors=True)
    os.makedirs(staging)
    record.update(rewrite_points(os.path.join(run, "points.laz"), os.path.join(staging, "points.laz"), record))
    if os.path.exists(os.path.join(run, "points.copc.laz")):
        # the same edit on the COPC octree: same nodes, their points edited (never a stale copy left beside)
        copc = rewrite_copc(os.path.join(run, "points.copc.laz"), os.path.join(staging, "points.copc.laz"),
                            lambda points: edit_points(points, record))
        if (copc["points_in"], copc["points_out"]) != (record["points_in"], record["points_out"]):
            raise RuntimeError(f"{run}: points.copc.laz gives {copc['points_in']:,} -> {copc['points_out']:,} "
                               f"points, points.laz {record['points_in']:,} -> {record['points_out']:,}: the two "
                               "files are not of one run")
    layer, stats = layer_with_figures(layer, elements, layer.get("crs_wkt"))
    with open(os.path.join(staging, "spaces.geojson"), "w") as f:
        json.dump(layer, f)
    write_spaces_gpkg(layer, os.path.join(staging, "spaces.gpkg"),
                      parse_crs({"wkt": layer["crs_wkt"]}) if layer.get("crs_wkt") else None)
    with open(os.path.join(staging, "elements.json"), "w") as f:
        json.dump(elements, f, indent=1)
    draw_plan(layer, elements, os.path.join(staging, "floorplan.png"), os.path.join(staging, "floorplan.svg"),
              crs_known=bool(layer.get("crs") or layer.get("crs_wkt")))
    from tiles.config import setting

    if setting("outputs.ifc"):
        from engine.outputs.ifc import write_ifc

        write_ifc(staging)
    metrics = _edited_metrics(metrics, record, run, len(layer["features"]))
    with open(os.path.join(staging, "metrics.json"), "w") as f:
        json.dump(metrics, f, indent=1)
    write_report(staging, metrics=metrics, statistics=stats)
    os.makedirs(out, exist_ok=True)
    for name in sorted(os.listdir(staging), key=lambda n: n == "report.html"):
        os.replace(os.path.join(staging, name), os.path.join(out, name))
    os.rmdir(staging)
    return record
