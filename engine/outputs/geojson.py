"""The spaces for GIS tools: one feature per space, its footprint polygon in world coordinates, as GeoJSON
(``spaces.geojson``) and GeoPackage (``spaces.gpkg``).

Coordinates are the building's own world x, y in the input's CRS (when it had
one), not longitude and latitude.  GDAL (and so QGIS) reads a GeoJSON as WGS 84
unless told otherwise: the collection names its CRS in the ``crs`` member GDAL
reads (``urn:ogc:def:crs:EPSG::<code>``, else the WKT; :func:`tiles.crs.geojson_crs_member`),
and keeps the WKT in ``crs_wkt``.  Exterior rings run counter-clockwise, holes
clockwise (RFC 7946).  The GeoPackage carries the same features with the CRS in
its own tables (written through pyogrio, GDAL's writer).
"""
from __future__ import annotations

import json
import os
import warnings
from typing import Any

import numpy as np
from pyproj import CRS
from shapely.geometry import MultiPolygon, Polygon, mapping, shape
from shapely.geometry.polygon import orient

from engine.spaces.document import SpaceParse
from tiles.crs import geojson_crs_member, horizontal


def oriented(geometry: dict[str, Any]) -> dict[str, Any]:
    """A GeoJSON (Multi)Polygon with counter-clockwise exterior rings and clockwise holes (RFC 7946)."""
    g = shape(geometry)
    if isinstance(g, Polygon):
        g = orient(g, 1.0)
    elif isinstance(g, MultiPolygon):
        g = MultiPolygon([orient(p, 1.0) for p in g.geoms])
    else:
        return geometry
    return json.loads(json.dumps(mapping(g)))  # tuples as lists, as the rest of the document


def spaces_feature_collection(parse: SpaceParse, crs: CRS | None = None) -> dict[str, Any]:
    """A GeoJSON FeatureCollection of the spaces (properties: id, area_m2, floor, z_min, z_max, point_count).

    ``crs``: the input's CRS; its horizontal part is named in the ``crs`` member
    (GDAL's reading) and as WKT in ``crs_wkt`` (the footprints are 2D).
    """
    feats = []
    for s in parse.spaces:
        feats.append({"type": "Feature", "id": s.id, "geometry": oriented(s.footprint),
                      "properties": {"id": s.id, "area_m2": round(s.area_m2, 3), "floor": s.floor,
                                     "z_min": round(s.z_range[0], 3), "z_max": round(s.z_range[1], 3),
                                     "point_count": s.point_count}})
    fc: dict[str, Any] = {"type": "FeatureCollection"}
    if crs is not None:
        flat = horizontal(crs)
        fc["crs"] = geojson_crs_member(flat)
        fc["crs_wkt"] = flat.to_wkt()
    fc["features"] = feats
    return fc


def write_spaces_geojson(parse: SpaceParse, path: str | os.PathLike, crs: CRS | None = None) -> str:
    """Write the spaces' footprints as GeoJSON to ``path``; returns the path."""
    path = os.fspath(path)
    parent = os.path.dirname(os.path.abspath(path))
    os.makedirs(parent, exist_ok=True)
    with open(path, "w") as f:
        json.dump(spaces_feature_collection(parse, crs), f)
    return path


def _field(values: list[Any]) -> tuple[np.ndarray, np.ndarray | None]:
    """A property's column for the GeoPackage (int64, float64, bool or text) and its null mask (None: no null)."""
    present = [v for v in values if v is not None]
    null = np.array([v is None for v in values])
    if present and all(isinstance(v, bool) for v in present):
        col = np.array([bool(v) for v in values])
    elif present and all(isinstance(v, int) and not isinstance(v, bool) for v in present):
        col = np.array([0 if v is None else v for v in values], dtype=np.int64)
    elif present and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in present):
        col = np.array([np.nan if v is None else v for v in values], dtype=np.float64)
    else:
        col = np.array(["" if v is None else (v if isinstance(v, str) else json.dumps(v)) for v in values],
                       dtype=object)
    return col, (null if null.any() else None)


def write_spaces_gpkg(collection: dict[str, Any], path: str | os.PathLike, crs: CRS | None = None) -> str:
    """Write a spaces FeatureCollection (:func:`spaces_feature_collection`, statistics added or not) as a
    GeoPackage layer ``spaces`` with the CRS's horizontal part; returns the path."""
    from pyogrio.raw import write

    path = os.fspath(path)
    feats = collection.get("features", [])
    names: list[str] = []
    for f in feats:
        names += [k for k in f.get("properties", {}) if k not in names]
    geoms = [shape(f["geometry"]) for f in feats]
    multi = any(isinstance(g, MultiPolygon) for g in geoms)
    wkb = np.array([g.wkb for g in geoms], dtype=object)
    cols, masks = zip(*[_field([f.get("properties", {}).get(n) for f in feats]) for n in names]) if names \
        else ((), ())
    field_mask = [m if m is not None else np.zeros(len(feats), bool) for m in masks] if any(
        m is not None for m in masks) else None
    if os.path.exists(path):
        os.remove(path)
    with warnings.catch_warnings():  # no CRS (local coordinates) is said by the GeoPackage itself: undefined
        warnings.filterwarnings("ignore", message=".*'crs' was not provided", category=UserWarning)
        write(path, wkb, list(cols), names, field_mask=field_mask, layer="spaces", driver="GPKG",
              geometry_type="MultiPolygon" if multi else "Polygon", promote_to_multi=multi,
              crs=None if crs is None else horizontal(crs).to_wkt())
    return path
