"""Coordinate reference systems through pyproj: a source's CRS record parsed, compared and written out.

A CRS record (``meta.crs``, :func:`tiles.ingest.lasformat.crs_of`) holds what a
source said: ``wkt`` text, GeoTIFF ``geotiff`` keys and/or an ``epsg`` code.
:func:`parse_crs` turns any of them into a :class:`pyproj.CRS` (GeoTIFF keys
naming a projected or geographic code, with a vertical code when given), so that
the same CRS said two ways (WKT in one file, GeoTIFF keys in another) compares
equal (:func:`same_crs`), and the outputs name it the way GIS tools read it
(:func:`geojson_crs_member`, :func:`crs_wkt`).
"""
from __future__ import annotations

import logging
from typing import Any

from pyproj import CRS
from pyproj.exceptions import CRSError

logger = logging.getLogger(__name__)

#: GeoTIFF keys: projected CRS, geographic CRS, vertical CRS (a value of 32767 is "user-defined").
_PROJECTED, _GEOGRAPHIC, _VERTICAL = 3072, 2048, 4096
_USER_DEFINED = 32767


def _geotiff_codes(record: dict[str, Any]) -> tuple[int | None, int | None]:
    """The horizontal and vertical EPSG codes the GeoTIFF keys name (None where they name none)."""
    keys = (record.get("geotiff") or {}).get("keys") or []
    found: dict[int, int] = {}
    for kid, loc, _count, value in keys:
        if kid in (_PROJECTED, _GEOGRAPHIC, _VERTICAL) and loc == 0 and 0 < value < _USER_DEFINED:
            found.setdefault(kid, int(value))
    horizontal = found.get(_PROJECTED, found.get(_GEOGRAPHIC, record.get("epsg")))
    return horizontal, found.get(_VERTICAL)


def parse_crs(record: dict[str, Any] | None) -> CRS | None:
    """The :class:`pyproj.CRS` of a CRS record: its WKT, else its GeoTIFF keys' EPSG codes, else None.

    A record pyproj cannot read (user-defined GeoTIFF keys, broken WKT) gives None
    with a warning: the outputs then carry no CRS rather than a wrong one.
    """
    if not record:
        return None
    try:
        if record.get("wkt"):
            return CRS.from_wkt(record["wkt"])
        horizontal, vertical = _geotiff_codes(record)
        if horizontal is None:
            return None
        return CRS.from_user_input(f"EPSG:{horizontal}" + (f"+{vertical}" if vertical else ""))
    except CRSError as e:
        logger.warning("coordinate reference system not understood (%s): the outputs carry none", e)
        return None


def horizontal(crs: CRS) -> CRS:
    """The horizontal part of a compound CRS (the CRS itself otherwise)."""
    return crs.sub_crs_list[0] if crs.is_compound and crs.sub_crs_list else crs


def same_crs(a: dict[str, Any], b: dict[str, Any]) -> bool:
    """Whether two CRS records name the same CRS, however each is written (WKT, GeoTIFF keys, EPSG code).

    A compound CRS matches a plain one with its horizontal part (one file may
    leave the heights' datum unsaid).  Records pyproj cannot read compare as given.
    """
    ca, cb = parse_crs(a), parse_crs(b)
    if ca is None or cb is None:
        return (ca is None and cb is None and a.get("wkt") == b.get("wkt") and a.get("epsg") == b.get("epsg")
                and str((a.get("geotiff") or {}).get("keys")) == str((b.get("geotiff") or {}).get("keys")))
    if ca.equals(cb, ignore_axis_order=True):
        return True
    if ca.is_compound != cb.is_compound:
        return horizontal(ca).equals(horizontal(cb), ignore_axis_order=True)
    return False


def crs_wkt(crs: CRS | None) -> str | None:
    """WKT (2019) of a CRS, None without one."""
    return None if crs is None else crs.to_wkt()


def geojson_crs_member(crs: CRS | None) -> dict[str, Any] | None:
    """The GeoJSON ``crs`` member GDAL (and so QGIS) reads: the OGC URN of the CRS's EPSG code
    (``urn:ogc:def:crs:EPSG::32633``), else its WKT; None without a CRS."""
    if crs is None:
        return None
    code = crs.to_epsg()
    if code is not None:
        return {"type": "name", "properties": {"name": f"urn:ogc:def:crs:EPSG::{code}"}}
    return {"type": "name", "properties": {"name": crs.to_wkt()}}
