"""PCD input (the Point Cloud Library's format) through pypcd4.

Every encoding PCL writes: ``ascii``, ``binary`` and ``binary_compressed``
(LZF); every field kept (:mod:`tiles.ingest.fields`: PCL's packed ``rgb`` as the
LAS colour, anything else as an extra dimension of its type; padding fields
``_`` dropped; a field of ``COUNT`` n as n dimensions).  The ``VIEWPOINT`` is
recorded in the source info, not applied (PCL's own readers do not apply it
to the points either).

A ``binary`` file's records are memory-mapped, so each task reads only its
own rows.  ``ascii`` and ``binary_compressed`` data cannot be entered in the
middle (the compressed block is one LZF stream, column by column), so one task
reads such a file whole and cuts it into parts there.  Coordinates are stored
on a 0.1 mm grid (``buildingparser.ingest.scale``) around a round offset near
the first point.
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

EXTENSIONS = (".pcd",)
#: A PCD header is ~11 short lines; more than this many bytes before ``DATA`` is not a PCD file.
MAX_HEADER_BYTES = 1 << 16


def read_header(local: str, path: str) -> tuple[Any, int]:
    """``(pypcd4 MetaData, byte offset of the data)`` of a PCD file; a clear error if it is not one."""
    from pydantic import ValidationError
    from pypcd4.pypcd4 import MetaData

    lines: list[str] = []
    offset = 0
    with open(local, "rb") as f:
        for raw in f:
            offset += len(raw)
            if offset > MAX_HEADER_BYTES:
                raise UserError(path, "not a PCD file: no DATA line in its header")
            try:
                line = raw.decode("ascii").strip()
            except UnicodeDecodeError:
                raise UserError(path, "not a PCD file: its header is not text") from None
            if not line or line.startswith("#"):
                continue
            lines.append(line)
            if line.upper().startswith("DATA"):
                break
        else:
            raise UserError(path, "not a PCD file: no DATA line in its header")
    try:
        meta = MetaData.parse_header(lines)
    except (ValidationError, ValueError, KeyError) as exc:
        first = str(exc).splitlines()[0]
        raise UserError(path, f"not a valid PCD header ({first})") from None
    return meta, offset


def _encoding(meta: Any) -> str:
    return str(getattr(meta.data, "value", meta.data)).lower()


class PcdReader(RecordReader):
    """A PCD file."""

    format = "pcd"

    def __init__(self, path: str, storage_options: dict[str, Any] | None = None):
        self.path = path
        self.storage_options = storage_options
        check_file(path, storage_options)
        with local_copy(path, storage_options) as local:
            meta, self.data_offset = read_header(local, path)
            self.encoding = _encoding(meta)
            self.mapped = self.encoding == "binary"  # rows of a binary file are memory-mapped
            self.count = int(meta.points)
            if not self.count:
                raise UserError(path, "empty point cloud: POINTS 0")
            dtype = meta.build_dtype()
            self.fields: FieldMap = field_map(dtype, path)
            self.dimensions = self.fields.dimensions(dtype)
            self.viewpoint = [float(v) for v in meta.viewpoint]
            first = self._records(local, 0, 1)
            self._first = np.array([float(first[a][0]) for a in self.fields.xyz])
        self.expected_count = self.count

    def _records(self, local: str, start: int, stop: int) -> np.ndarray:
        """Records ``[start, stop)``: memory-mapped rows of a binary file, else the whole file decoded."""
        meta, offset = read_header(local, self.path)
        dtype = meta.build_dtype()
        if self.encoding == "binary":
            need = offset + self.count * dtype.itemsize
            import os

            if os.path.getsize(local) < need:
                raise UserError(self.path, f"truncated: {self.count:,} points need {need:,} bytes")
            rows = np.memmap(local, dtype=dtype, mode="r", offset=offset, shape=(self.count,))
            return np.array(rows[start:stop])
        from pypcd4 import PointCloud

        try:
            with open(local, "rb") as f:
                data = PointCloud.from_fileobj(f).pc_data
        except Exception as exc:  # noqa: BLE001 - numpy, lzf and pypcd4 raise their own
            raise UserError(self.path, f"unreadable {self.encoding} PCD data ({type(exc).__name__}: {exc})") \
                from None
        if len(data) != self.count:
            raise UserError(self.path, f"the header promises {self.count:,} points, the data holds {len(data):,}")
        return data[start:stop]

    def first_point(self) -> np.ndarray:
        return self._first

    def read(self, spec: Any, grid: Quantization) -> Iterator[PartResult]:
        start, stop, part_points = spec
        with local_copy(self.path, self.storage_options) as local:
            records = self._records(local, start, stop)
        for a in range(0, len(records), part_points):
            yield self.fields.columns(records[a:a + part_points], grid, self.path)

    def source_info(self, stats: list[dict[str, Any]]) -> dict[str, Any]:
        return {"encoding": self.encoding, "points": self.count, "viewpoint": self.viewpoint, "scale": grid_scale()}
