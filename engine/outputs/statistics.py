"""Space statistics, the first of the paper's "emerging applications" (section 5.3).

Per space, from its footprint (``spaces.geojson``) and the detected elements
assigned to it (``elements.json``, by ``space_id``):

* ``area_m2`` and ``perimeter_m``: area and boundary length of the footprint
  polygon (holes included in the boundary), in the world's horizontal units;
* ``height_m``: ``z_max - z_min`` of the space when the footprint has them;
* ``points``: the space's point count when known;
* ``elements``: the number of detected elements of each of the 12 classes;
* ``wall_area_m2``, ``window_area_m2`` and ``window_to_wall``: the
  window-to-wall ratio, the summed *face area* of the space's windows over that
  of its walls, where the face area of a box is its longer horizontal side times
  its height (the side a wall or window shows the room); None without walls.

``total`` sums the same over the building (its ratio from the summed areas).
:func:`add_statistics_to_geojson` writes them into the features' properties
(flat names, so that GIS tools show them as columns).
"""
from __future__ import annotations

import copy
from collections.abc import Iterable, Sequence
from typing import Any

from tiles.classes import ELEMENT_CLASSES


def _features(spaces: Any) -> list[dict[str, Any]]:
    """Spaces as ``{"id", "geometry", "properties"}`` from a FeatureCollection, features, or plain space dicts."""
    if isinstance(spaces, dict) and spaces.get("type") == "FeatureCollection":
        spaces = spaces.get("features", [])
    out = []
    for s in spaces:
        if not isinstance(s, dict):  # an engine.spaces.document.Space
            s = {"id": s.id, "footprint": s.footprint, "z_range": s.z_range, "point_count": s.point_count}
        if s.get("type") == "Feature":
            props = dict(s.get("properties") or {})
            sid = props.get("id", s.get("id"))
            geom = s.get("geometry")
        else:
            props = {k: v for k, v in s.items() if k not in ("footprint", "geometry")}
            sid = s.get("id")
            geom = s.get("footprint", s.get("geometry"))
            if "z_range" in s and s["z_range"]:
                props.setdefault("z_min", s["z_range"][0])
                props.setdefault("z_max", s["z_range"][1])
        if sid is None:
            raise ValueError("every space needs an id")
        out.append({"id": int(sid), "geometry": geom, "properties": props})
    return out


def face_area(size: Sequence[float]) -> float:
    """Face area of a box: its longer horizontal side times its height."""
    return float(max(size[0], size[1]) * size[2])


def _class_name(e: dict[str, Any]) -> str | None:
    name = e.get("class")
    if name in ELEMENT_CLASSES:
        return name
    code = e.get("class_code")
    if code is not None and 0 <= int(code) < len(ELEMENT_CLASSES):
        return ELEMENT_CLASSES[int(code)]
    return None


def space_statistics(spaces: Any, elements: Iterable[dict[str, Any]]) -> dict[str, Any]:
    """Area, perimeter, element counts and window-to-wall ratio of every space, and the building's totals.

    Parameters
    ----------
    spaces
        The ``spaces.geojson`` FeatureCollection (or its features), or space dicts with ``id``,
        ``footprint`` (GeoJSON geometry) and optionally ``z_range`` / ``point_count``, or
        :class:`engine.spaces.document.Space` objects.
    elements
        ``elements.json`` records (``class`` or ``class_code``, ``space_id``, ``size``).

    Returns
    -------
    dict
        ``{"spaces": [{"id", "area_m2", "perimeter_m", "height_m", "points", "elements": {class: n},
        "wall_area_m2", "window_area_m2", "window_to_wall"}], "total": {... the same summed ...}}``,
        spaces in id order.
    """
    from shapely.geometry import shape

    feats = sorted(_features(spaces), key=lambda f: f["id"])
    rows: dict[int, dict[str, Any]] = {}
    for f in feats:
        geom = f["geometry"]
        area = perim = 0.0
        if geom and geom.get("coordinates"):
            g = shape(geom)
            area, perim = float(g.area), float(g.length)
        p = f["properties"]
        height = None
        if p.get("z_min") is not None and p.get("z_max") is not None:
            height = float(p["z_max"]) - float(p["z_min"])
        points = p.get("point_count", p.get("points"))
        rows[f["id"]] = {"id": f["id"], "area_m2": area, "perimeter_m": perim, "height_m": height,
                         "points": None if points is None else int(points),
                         "elements": {c: 0 for c in ELEMENT_CLASSES}, "wall_area_m2": 0.0, "window_area_m2": 0.0,
                         "window_to_wall": None}
    unassigned = 0
    for e in elements:
        name = _class_name(e)
        row = rows.get(int(e.get("space_id", -1)))
        if name is None:
            continue
        if row is None:
            unassigned += 1
            continue
        row["elements"][name] += 1
        if name == "wall":
            row["wall_area_m2"] += face_area(e["size"])
        elif name == "window":
            row["window_area_m2"] += face_area(e["size"])
    for row in rows.values():
        if row["wall_area_m2"] > 0:
            row["window_to_wall"] = row["window_area_m2"] / row["wall_area_m2"]
    out_rows = [rows[k] for k in sorted(rows)]
    wall = sum(r["wall_area_m2"] for r in out_rows)
    window = sum(r["window_area_m2"] for r in out_rows)
    total = {"spaces": len(out_rows), "area_m2": sum(r["area_m2"] for r in out_rows),
             "perimeter_m": sum(r["perimeter_m"] for r in out_rows),
             "points": sum(r["points"] or 0 for r in out_rows),
             "elements": {c: sum(r["elements"][c] for r in out_rows) for c in ELEMENT_CLASSES},
             "wall_area_m2": wall, "window_area_m2": window, "window_to_wall": window / wall if wall > 0 else None,
             "elements_outside_spaces": unassigned}
    return {"spaces": out_rows, "total": total}


def add_statistics_to_geojson(geojson: dict[str, Any], stats: dict[str, Any]) -> dict[str, Any]:
    """A copy of a spaces FeatureCollection with each feature's statistics added to its properties.

    Added properties: ``perimeter_m``, ``stats_area_m2``, ``wall_area_m2``, ``window_area_m2``,
    ``window_to_wall`` and ``n_<class>`` per element class (existing properties are kept).
    """
    if geojson.get("type") != "FeatureCollection":
        raise ValueError("expected a GeoJSON FeatureCollection")
    by_id = {r["id"]: r for r in stats.get("spaces", [])}
    out = copy.deepcopy(geojson)
    for feat in out.get("features", []):
        props = feat.setdefault("properties", {})
        sid = props.get("id", feat.get("id"))
        row = by_id.get(None if sid is None else int(sid))
        if row is None:
            continue
        props.update({"perimeter_m": round(row["perimeter_m"], 3), "stats_area_m2": round(row["area_m2"], 3),
                      "wall_area_m2": round(row["wall_area_m2"], 3), "window_area_m2": round(row["window_area_m2"], 3),
                      "window_to_wall": None if row["window_to_wall"] is None else round(row["window_to_wall"], 4)})
        props.update({f"n_{c}": int(n) for c, n in row["elements"].items()})
    return out

