"""E57 input (ASTM E2807) through pye57, an optional extra: ``pip install 'buildingparser[e57]'``.

Each scan of ``/data3D`` is read with its pose applied (rotation quaternion then
translation), cartesian or spherical.  One task per scan decodes it in blocks of
``part_points`` records and stages each block as a part, so memory stays
bounded by a part even for a scan larger than memory (E57 compressed vectors
cannot be entered in the middle, so a scan is not split among tasks).

Stored per point: ``x``, ``y``, ``z`` (0.1 mm grid), ``red``/``green``/``blue``
when the scans have colour (8- and 16-bit limits kept, other ``colorLimits``
mapped to 0-65535), ``intensity`` (uint16: the scan's ``intensityLimits``
mapped to 0-65535, or the values rounded when the scan has no limits; limits
and pose values may be integer, scaled-integer or float nodes; records flagged
``isIntensityInvalid``/``isColorInvalid`` get 0), ``scan_index`` (which scan), and ``row_index``/``column_index`` of
structured (gridded) scans.  Records flagged invalid (``cartesianInvalidState``
or ``sphericalInvalidState`` non-zero: no measured point) are not points: they
are counted in the source info and a warning, not stored.
"""
from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np

from tiles.errors import UserError
from tiles.ingest.files import check_file, local_copy
from tiles.ingest.reader import PartResult, Quantization, Reader
from tiles.ingest.text import color_dimensions
from tiles.schema import Dimension, coordinate_dimensions

EXTENSIONS = (".e57",)
_COLOURS = ("colorRed", "colorGreen", "colorBlue")


def _pye57():
    try:
        import pye57
    except ImportError:
        raise UserError(None, "reading E57 needs the optional pye57 package: pip install 'buildingparser[e57]'") \
            from None
    return pye57


class E57Reader(Reader):
    """An E57 file: one task per scan."""

    format = "e57"

    def __init__(self, path: str, storage_options: dict[str, Any] | None = None):
        self.path = path
        self.storage_options = storage_options
        check_file(path, storage_options)
        pye57 = _pye57()
        self.scans: list[dict[str, Any]] = []
        with local_copy(path, storage_options) as local:
            try:
                e = pye57.E57(local)
            except Exception as exc:  # noqa: BLE001 - libe57 raises its own exceptions
                raise UserError(path, f"not a readable E57 file ({type(exc).__name__}: {exc})") from None
            try:
                self.coordinate_metadata = _string(e.root, "coordinateMetadata")
                for i in range(e.scan_count):
                    h = e.get_header(i)
                    fields = set(h.point_fields)
                    if {"cartesianX", "cartesianY", "cartesianZ"} <= fields:
                        system = "cartesian"
                    elif {"sphericalRange", "sphericalAzimuth", "sphericalElevation"} <= fields:
                        system = "spherical"
                    else:
                        raise UserError(path, f"scan {i} has neither cartesian nor spherical coordinates")
                    rotation, translation = _pose(h.node, path, i)
                    self.scans.append({
                        "index": i, "count": int(h.point_count), "system": system,
                        "rotation": rotation, "translation": translation,
                        "color": {"colorRed", "colorGreen", "colorBlue"} <= fields,
                        "color_limits": {k: limits_of(h.node, "colorLimits", k) for k in _COLOURS},
                        "intensity": "intensity" in fields,
                        "intensity_limits": limits_of(h.node, "intensityLimits", "intensity"),
                        "grid": {"rowIndex", "columnIndex"} <= fields,
                        "invalid": f"{system}InvalidState" if f"{system}InvalidState" in fields else None,
                        "intensity_invalid": "isIntensityInvalid" in fields,
                        "color_invalid": "isColorInvalid" in fields,
                        "name": _string(h.node, "name"),
                    })
            finally:
                e.close()
        self.expected_count = None  # invalid records are not points
        if not sum(s["count"] for s in self.scans):
            raise UserError(path, "empty point cloud: no scan holds points")
        dims = coordinate_dimensions()
        if any(s["color"] for s in self.scans):
            dims += color_dimensions()
        if any(s["intensity"] for s in self.scans):
            dims.append(Dimension("intensity", "uint16", "las", "intensity (scan limits mapped to 0-65535)",
                                  {"name": "intensity"}))
        dims.append(Dimension("scan_index", "uint16", "extra", "E57 scan of the point",
                              {"name": "scan_index", "type": "u2", "description": "E57 scan index"}))
        if any(s["grid"] for s in self.scans):
            for n in ("row_index", "column_index"):
                dims.append(Dimension(n, "uint32", "extra", f"E57 {n.replace('_', ' ')} of structured scans",
                                      {"name": n, "type": "u4", "description": f"E57 {n}"}))
        self.dimensions = dims
        self._first = self._first_point()

    def _first_point(self) -> np.ndarray | None:
        s = next(s for s in self.scans if s["count"])
        return np.asarray(s["translation"], dtype=np.float64)

    def first_point(self) -> np.ndarray | None:
        return self._first

    def crs(self) -> dict[str, Any] | None:
        text = (self.coordinate_metadata or "").strip()
        if text[:6].upper() in ("PROJCS", "GEOGCS", "COMPD_", "GEOCCS") or text[:8].upper() in ("PROJCRS[", "GEOGCRS["):
            return {"wkt": text}
        return None

    def plan(self, part_points: int) -> list[Any]:
        return [(s["index"], part_points) for s in self.scans if s["count"]]

    def parts_of(self, spec: Any) -> int:
        index, part_points = spec
        return -(-self.scans[index]["count"] // part_points)

    def read(self, spec: Any, grid: Quantization) -> Iterator[PartResult]:
        index, part_points = spec
        scan = self.scans[index]
        pye57 = _pye57()
        from pye57 import libe57

        names = ({"cartesian": ["cartesianX", "cartesianY", "cartesianZ"],
                  "spherical": ["sphericalRange", "sphericalAzimuth", "sphericalElevation"]}[scan["system"]])
        dtypes = dict.fromkeys(names, "d")
        if scan["color"]:
            dtypes.update({"colorRed": "d", "colorGreen": "d", "colorBlue": "d"})
            if scan.get("color_invalid"):
                dtypes["isColorInvalid"] = "i1"
        if scan["intensity"]:
            dtypes["intensity"] = "d"
            if scan.get("intensity_invalid"):
                dtypes["isIntensityInvalid"] = "i1"
        if scan["grid"]:
            dtypes.update({"rowIndex": "q", "columnIndex": "q"})  # libe57 buffers: b B h H l L q, f d
        if scan["invalid"]:
            dtypes[scan["invalid"]] = "i1"
        want = {d.name for d in self.dimensions}
        rot = np.asarray(scan["rotation"]).reshape(3, 3)
        tr = np.asarray(scan["translation"])
        with local_copy(self.path, self.storage_options) as local:
            e = pye57.E57(local)
            try:
                h = e.get_header(index)
                arrays = {k: np.empty(part_points, dtype=t) for k, t in dtypes.items()}
                buffers = libe57.VectorSourceDestBuffer()
                for k, a in arrays.items():
                    buffers.append(libe57.SourceDestBuffer(e.image_file, k, a, part_points, True, True))
                reader = h.points.reader(buffers)
                try:
                    left = scan["count"]
                    while left > 0:
                        got = int(reader.read())
                        if got <= 0:
                            raise UserError(self.path, f"scan {index}: the data ends {left:,} records early")
                        left -= got
                        yield self._columns(scan, {k: a[:got] for k, a in arrays.items()}, rot, tr, grid, want)
                finally:
                    reader.close()
            except UserError:
                raise
            except Exception as exc:  # noqa: BLE001
                raise UserError(self.path, f"scan {index}: unreadable E57 data ({type(exc).__name__}: {exc})") \
                    from None
            finally:
                e.close()

    def _columns(self, scan, data, rot, tr, grid: Quantization, want: set[str]) -> PartResult:
        n = len(next(iter(data.values())))
        keep = np.ones(n, dtype=bool)
        if scan["invalid"]:
            keep = data[scan["invalid"]] == 0
        if scan["system"] == "cartesian":
            xyz = np.stack([data["cartesianX"], data["cartesianY"], data["cartesianZ"]], axis=1)[keep]
        else:
            from pye57.utils import convert_spherical_to_cartesian

            rae = np.stack([data["sphericalRange"], data["sphericalAzimuth"], data["sphericalElevation"]], axis=1)
            xyz = convert_spherical_to_cartesian(rae[keep])
        xyz = xyz @ rot.T + tr
        if not np.isfinite(xyz).all():
            raise UserError(self.path, f"scan {scan['index']}: non-finite coordinates")
        cols = grid.quantize(xyz, self.path)
        m = len(xyz)
        if "red" in want:
            for c, k in (("red", "colorRed"), ("green", "colorGreen"), ("blue", "colorBlue")):
                cols[c] = _colour(data[k][keep], scan["color_limits"][k], data, keep) if scan["color"] \
                    else np.zeros(m, np.uint16)
        if "intensity" in want:
            cols["intensity"] = np.zeros(m, np.uint16)
            if scan["intensity"]:
                v = _mapped(data["intensity"][keep], scan["intensity_limits"], 65535.0)
                if scan.get("intensity_invalid"):
                    v[data["isIntensityInvalid"][keep] != 0] = 0
                cols["intensity"] = v
        cols["scan_index"] = np.full(m, scan["index"], dtype=np.uint16)
        if "row_index" in want:
            cols["row_index"] = data["rowIndex"][keep].astype(np.uint32) if scan["grid"] else np.zeros(m, np.uint32)
            cols["column_index"] = (data["columnIndex"][keep].astype(np.uint32) if scan["grid"]
                                    else np.zeros(m, np.uint32))
        return PartResult(cols, {"scan": scan["index"], "records": n, "invalid": int(n - m)})

    def source_info(self, stats: list[dict[str, Any]]) -> dict[str, Any]:
        return {"scans": [{"index": s["index"], "name": s["name"], "records": s["count"],
                           "coordinates": s["system"], "structured": s["grid"],
                           "intensity_limits": s["intensity_limits"],
                           "invalid_records": int(sum(t.get("invalid", 0) for t in stats
                                                      if t.get("scan") == s["index"]))} for s in self.scans],
                "invalid_records": int(sum(s.get("invalid", 0) for s in stats)),
                "coordinate_metadata": self.coordinate_metadata}

    def warnings(self, info: dict[str, Any]) -> list[str]:
        if info.get("invalid_records"):
            return [f"{self.path}: {info['invalid_records']:,} records flagged invalid (no measured point) "
                    "were not stored"]
        return []


def _string(node, name: str) -> str | None:
    try:
        if node.isDefined(name):
            return str(node[name].value())
    except Exception:  # noqa: BLE001
        return None
    return None


def _number(node) -> float:
    """The value of a numeric E57 node of any type (integer, scaled integer or float)."""
    for name in ("scaledValue", "value"):
        get = getattr(node, name, None)
        if get is not None:
            return float(get())
    raise TypeError(f"{type(node).__name__} is not a numeric E57 node")


def limits_of(node, group: str, field: str) -> list[float] | None:
    """``[minimum, maximum]`` of ``field`` in ``intensityLimits``/``colorLimits`` of any node type, None when absent."""
    try:
        if not node.isDefined(group):
            return None
        g = node[group]
        names = (f"{field}Minimum", f"{field}Maximum")
        if not all(g.isDefined(n) for n in names):
            return None
        lo, hi = (_number(g[n]) for n in names)
    except Exception:  # noqa: BLE001 - a malformed limits node is as good as none
        return None
    return [lo, hi] if np.isfinite([lo, hi]).all() and hi > lo else None


def _pose(node, path: str, index: int) -> tuple[list[float], list[float]]:
    """A scan's pose as a row-major 3x3 rotation and a translation (identity and zero when absent)."""
    rotation, translation = np.eye(3), np.zeros(3)
    try:
        if node.isDefined("pose"):
            pose = node["pose"]
            if pose.isDefined("rotation"):
                q = np.array([_number(pose["rotation"][k]) for k in ("w", "x", "y", "z")])
                norm = float(np.linalg.norm(q))
                if not np.isfinite(q).all() or norm == 0:
                    raise UserError(path, f"scan {index}: its pose rotation is not a quaternion ({q.tolist()})")
                w, x, y, z = q / norm
                rotation = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
            if pose.isDefined("translation"):
                translation = np.array([_number(pose["translation"][k]) for k in ("x", "y", "z")])
                if not np.isfinite(translation).all():
                    raise UserError(path, f"scan {index}: its pose translation is not finite")
    except UserError:
        raise
    except Exception as exc:  # noqa: BLE001 - libe57 raises its own exceptions
        raise UserError(path, f"scan {index}: unreadable pose ({type(exc).__name__}: {exc})") from None
    return [float(v) for v in rotation.ravel()], [float(v) for v in translation]


def _mapped(v: np.ndarray, limits: list[float] | None, top: float) -> np.ndarray:
    """Values mapped from their limits to 0-``top`` (rounded as they are without limits), as uint16."""
    if limits:
        v = (v - limits[0]) / (limits[1] - limits[0]) * top
    return np.clip(np.rint(v), 0, 65535).astype(np.uint16)


def _colour(v: np.ndarray, limits: list[float] | None, data: dict[str, np.ndarray], keep: np.ndarray) -> np.ndarray:
    """A colour channel: 8-bit limits (or none) kept as they are, wider or fractional limits mapped to 0-65535."""
    if limits and limits[0] == 0 and limits[1] in (255.0, 65535.0):
        limits = None
    out = _mapped(v, limits, 65535.0)
    if "isColorInvalid" in data:
        out[data["isColorInvalid"][keep] != 0] = 0
    return out
