"""PLY input (Stanford polygon format: ScanNet, Open3D, CloudCompare, Meshlab exports) through plyfile.

The points are the ``vertex`` element: binary (either byte order) or ASCII,
with every scalar property kept (:mod:`tiles.ingest.fields`: colour as the LAS
colour, anything else as an extra dimension of its type).  Other elements
(the faces of a mesh, camera records) are not points: they are counted in the
source info and a warning.

A binary file's vertices are memory-mapped by plyfile, so each task reads only
its own rows.  An ASCII file (or a vertex element after a list-valued element,
which cannot be mapped) is read whole by one task and cut into parts there:
such files are small in practice (ASCII costs ~3x the bytes of binary).
Coordinates are stored on a 0.1 mm grid (``buildingparser.ingest.scale``)
around a round offset near the first point.
"""
from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np

from tiles.errors import UserError
from tiles.ingest.fields import FieldMap, RecordReader, field_map
from tiles.ingest.files import check_file, local_copy
from tiles.ingest.reader import PartResult, Quantization
from tiles.ingest.text import grid_scale

EXTENSIONS = (".ply",)


def _plyfile():
    import plyfile

    return plyfile


def _vertices(local: str, path: str) -> tuple[Any, Any]:
    """``(PlyData, vertex element)`` of a file, memory-mapped where plyfile can; a clear error otherwise."""
    plyfile = _plyfile()
    try:
        data = plyfile.PlyData.read(local, mmap=True)
    except (plyfile.PlyParseError, ValueError, OSError, EOFError) as exc:
        raise UserError(path, f"not a readable PLY file ({exc})") from None
    names = [e.name for e in data.elements]
    if "vertex" not in names:
        raise UserError(path, f"no vertex element (elements: {', '.join(names) or 'none'})")
    return data, data["vertex"]


class PlyReader(RecordReader):
    """A PLY file: its vertices are the points."""

    format = "ply"

    def __init__(self, path: str, storage_options: dict[str, Any] | None = None):
        self.path = path
        self.storage_options = storage_options
        check_file(path, storage_options)
        with local_copy(path, storage_options) as local:
            data, vertex = _vertices(local, path)
            records = vertex.data
            self.count = int(len(records))
            if not self.count:
                raise UserError(path, "empty point cloud: the vertex element holds no points")
            self.mapped = isinstance(records, np.memmap)
            self.encoding = "ascii" if data.text else ("binary_" + ("little" if data.byte_order == "<" else "big")
                                                        + "_endian")
            self.other_elements = {e.name: int(e.count) for e in data.elements if e.name != "vertex"}
            self.fields: FieldMap = field_map(records.dtype, path)
            self.dimensions = self.fields.dimensions(records.dtype)
            first = records[:1]
            self._first = np.array([float(first[a][0]) for a in self.fields.xyz])
            self.comments = [str(c) for c in data.comments][:20]
        self.expected_count = self.count

    def first_point(self) -> np.ndarray:
        return self._first

    def native_grid(self) -> Quantization | None:
        return None

    def read(self, spec: Any, grid: Quantization) -> Iterator[PartResult]:
        start, stop, part_points = spec
        with local_copy(self.path, self.storage_options) as local:
            _, vertex = _vertices(local, self.path)
            records = vertex.data
            if len(records) != self.count:
                raise UserError(self.path, "the file changed while it was read")
            for a in range(start, stop, part_points):
                chunk = np.array(records[a:min(a + part_points, stop)])
                yield self.fields.columns(chunk, grid, self.path)

    def source_info(self, stats: list[dict[str, Any]]) -> dict[str, Any]:
        return {"encoding": self.encoding, "vertices": self.count, "other_elements": self.other_elements,
                "comments": self.comments, "scale": grid_scale()}

    def warnings(self, info: dict[str, Any]) -> list[str]:
        other = info.get("other_elements") or {}
        if other:
            listed = ", ".join(f"{n} ({c:,})" for n, c in other.items())
            return [f"{self.path}: only the vertices are points; not stored: {listed}"]
        return []
