"""Footprint polygons of spaces: the union of their cells' aligned boxes, turned into world coordinates."""
from __future__ import annotations

from typing import Any

import shapely
from shapely import affinity
from shapely.geometry import MultiPolygon, Polygon, box, mapping

from engine.spaces.alignment import Frame


def polygonal(geom: Any) -> Polygon | MultiPolygon:
    """The polygonal part of a shapely geometry: a union or intersection of boxes returns, where boundaries only
    touch, a GeometryCollection of its polygons and the points or lines where they touch, which a GeoPackage
    layer of polygons does not allow and GIS tools do not draw; an empty Polygon when there is no area."""
    if isinstance(geom, (Polygon, MultiPolygon)):
        return geom
    polys = [p for g in getattr(geom, "geoms", []) if isinstance(g, (Polygon, MultiPolygon))
             for p in (g.geoms if isinstance(g, MultiPolygon) else [g]) if not p.is_empty]
    if not polys:
        return Polygon()
    return polys[0] if len(polys) == 1 else MultiPolygon(polys)


def union_footprint(rects: list[list[float]], frame: Frame) -> tuple[dict[str, Any], float]:
    """GeoJSON geometry (world x, y) of the union of aligned boxes ``[u0, v0, u1, v1]``, and its area in m².

    The cells of a space tile the plane without overlap and share exact edges,
    so the union is a clean polygon (with holes where a space surrounds another).
    """
    if not rects:
        return {"type": "Polygon", "coordinates": []}, 0.0
    geom = shapely.union_all([box(*r) for r in rects])
    area = float(geom.area)
    c, s = frame.cos_sin
    world = affinity.affine_transform(geom, [c, -s, s, c, frame.origin[0], frame.origin[1]])
    world = polygonal(shapely.set_precision(world, 1e-4))
    return mapping(world), area


def union_geojson(geoms: list[dict[str, Any]]) -> tuple[dict[str, Any], float]:
    """GeoJSON union of GeoJSON geometries (world x, y) and its area in m² (spaces joined after refinement)."""
    from shapely.geometry import shape

    shapes = [shape(g) for g in geoms if g.get("coordinates")]
    if not shapes:
        return {"type": "Polygon", "coordinates": []}, 0.0
    world = polygonal(shapely.set_precision(shapely.union_all(shapes), 1e-4))
    return mapping(world), float(world.area)


def clipped_footprint(rects: list[list[float]], frame: Frame, clip_rects: list[list[float]], clip_frame: Frame
                      ) -> tuple[dict[str, Any], float]:
    """GeoJSON (world) and area of the union of ``rects`` (in ``frame``) within the union of ``clip_rects``.

    A refined space's cells are boxes of its own frame that may reach beyond the
    space: its footprint is their union clipped to the space it came from.
    """
    def world(rs: list[list[float]], fr: Frame):
        c, s = fr.cos_sin
        g = shapely.union_all([box(*r) for r in rs])
        return affinity.affine_transform(g, [c, -s, s, c, fr.origin[0], fr.origin[1]])

    if not rects or not clip_rects:
        return {"type": "Polygon", "coordinates": []}, 0.0
    geom = polygonal(shapely.set_precision(world(rects, frame).intersection(world(clip_rects, clip_frame)), 1e-4))
    return mapping(geom), float(geom.area)
