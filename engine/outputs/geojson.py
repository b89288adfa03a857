"""The spaces as GeoJSON: one feature per space, its footprint polygon in world coordinates.

Coordinates are the building's own world x, y (the CRS of the input, if it had
one, named in the collection's ``crs_wkt`` member when known), not longitude
and latitude.
"""
from __future__ import annotations

import json
import os
from typing import Any

from engine.spaces.document import SpaceParse


def spaces_feature_collection(parse: SpaceParse, crs_wkt: str | None = None) -> dict[str, Any]:
    """A GeoJSON FeatureCollection of the spaces (properties: id, area_m2, floor, z_min, z_max, point_count)."""
    feats = []
    for s in parse.spaces:
        feats.append({"type": "Feature", "id": s.id, "geometry": s.footprint,
                      "properties": {"id": s.id, "area_m2": round(s.area_m2, 3), "floor": s.floor,
                                     "z_min": round(s.z_range[0], 3), "z_max": round(s.z_range[1], 3),
                                     "point_count": s.point_count}})
    fc: dict[str, Any] = {"type": "FeatureCollection", "features": feats}
    if crs_wkt:
        fc["crs_wkt"] = crs_wkt
    return fc


def write_spaces_geojson(parse: SpaceParse, path: str | os.PathLike, crs_wkt: str | None = None) -> str:
    """Write the spaces' footprints as GeoJSON to ``path``; returns the path."""
    path = os.fspath(path)
    parent = os.path.dirname(os.path.abspath(path))
    os.makedirs(parent, exist_ok=True)
    with open(path, "w") as f:
        json.dump(spaces_feature_collection(parse, crs_wkt), f)
    return path
