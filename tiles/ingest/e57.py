"""E57 input (ASTM E2807) through pye57, an optional extra: ``pip install 'buildingparser[e57]'``.

Each scan of ``/data3D`` is read with its pose applied (rotation quaternion then
translation), cartesian or spherical.  One task per scan decodes it in blocks of
``part_points`` records and stages each block as a part, so memory stays
bounded by a part even for a scan larger than memory (E57 compressed vectors
cannot be entered in the middle, so a scan is not split among tasks).

Stored per point: ``x``, ``y``, ``z`` (0.1 mm grid), ``red``/``green``/``blue``
when the scans have colour, ``intensity`` (uint16: the scan's
``intensityLimits`` mapped to 0-65535, or the values rounded when the scan has
no limits), ``scan_index`` (which scan), and ``row_index``/``column_index`` of
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
                    limits = None
                    if "intensityLimits" in h.scan_fields:
                        limits = [float(h.intensityMinimum), float(h.intensityMaximum)]
                    self.scans.append({
                        "index": i, "count": int(h.point_count), "system": system,
                        "rotation": [float(v) for v in h.rotation_matrix.ravel()],
                        "translation": [float(v) for v in h.translation],
                        "color": {"colorRed", "colorGreen", "colorBlue"} <= fields,
                        "intensity": "intensity" in fields, "intensity_limits": limits,
                        "grid": {"rowIndex", "columnIndex"} <= fields,
                        "invalid": ("cartesianInvalidState" if system == "cartesian" else "sphericalInvalidState")
                        if ({"cartesianInvalidState", "sphericalInvalidState"} & fields) else None,
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
            dtypes.update({"colorRed": "H", "colorGreen": "H", "colorBlue": "H"})
        if scan["intensity"]:
            dtypes["intensity"] = "d"
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
                cols[c] = data[k][keep].astype(np.uint16) if scan["color"] else np.zeros(m, np.uint16)
        if "intensity" in want:
            if scan["intensity"]:
                v = data["intensity"][keep]
                lim = scan["intensity_limits"]
                if lim and lim[1] > lim[0]:
                    v = (v - lim[0]) / (lim[1] - lim[0]) * 65535.0
                cols["intensity"] = np.clip(np.rint(v), 0, 65535).astype(np.uint16)
            else:
                cols["intensity"] = np.zeros(m, np.uint16)
        cols["scan_index"] = np.full(m, scan["index"], dtype=np.uint16)
        if "row_index" in want:
            cols["row_index"] = data["rowIndex"][keep].astype(np.uint32) if scan["grid"] else np.zeros(m, np.uint32)
            cols["column_index"] = (data["columnIndex"][keep].astype(np.uint32) if scan["grid"]
                                    else np.zeros(m, np.uint32))
        return PartResult(cols, {"scan": scan["index"], "records": n, "invalid": int(n - m)})

    def source_info(self, stats: list[dict[str, Any]]) -> dict[str, Any]:
        return {"scans": [{"index": s["index"], "name": s["name"], "records": s["count"],
                           "coordinates": s["system"], "structured": s["grid"],
                           "intensity_limits": s["intensity_limits"]} for s in self.scans],
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
