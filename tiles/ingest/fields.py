"""Point records with named fields (PLY vertices, PCD points) as store dimensions and columns.

A record array's fields map to the store as follows; every field is kept:

* ``x``, ``y``, ``z``: the coordinates (any float or integer type), on the
  store's grid;
* colour: ``red``/``green``/``blue`` (also ``r``/``g``/``b`` and PLY's
  ``diffuse_*``), and PCD's packed ``rgb``/``rgba`` (a float32 or uint32 holding
  8-bit channels), as the LAS colour dimensions (values as given: 0-255 for
  8-bit colour, scaled to 16 bits on export);
* any other scalar field (intensity, normals, curvature, labels, ...): an extra
  dimension of the same type, named after the field (made Zarr-safe, renamed
  ``source_<name>`` when it clashes with a reserved name such as
  ``classification`` or a standard LAS dimension such as ``gps_time``: see
  :func:`tiles.ingest.reader.safe_name`), except an unsigned ``intensity`` of
  at most 16 bits, which is the LAS intensity.

Fields with several values per point (PCD ``COUNT`` > 1) give one dimension per
value (``name_0``, ``name_1``, ...).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import laspy
import numpy as np

from tiles.errors import UserError
from tiles.ingest.reader import PartResult, Quantization, Reader, safe_name
from tiles.ingest.text import color_dimensions
from tiles.schema import Dimension, coordinate_dimensions

#: Colour field names of the formats, per channel.
COLOUR_NAMES = {"red": ("red", "r", "diffuse_red"), "green": ("green", "g", "diffuse_green"),
                "blue": ("blue", "b", "diffuse_blue")}
#: Packed colour fields (PCL): 8-bit channels in one 32-bit value, 0x00RRGGBB.
PACKED_COLOUR = ("rgb", "rgba")
#: numpy kinds an extra dimension can hold (LAS extra bytes: integers and floats).
_EXTRA_KINDS = "iuf"
#: Standard dimensions of LAS point format 7 (an extra dimension of the same name would be hidden by them).
LAS_STANDARD = frozenset(n.lower() for n in laspy.PointFormat(7).standard_dimension_names)


@dataclass(frozen=True)
class FieldMap:
    """How a record array's fields become store columns (picklable, made on the driver)."""

    xyz: tuple[str, str, str]
    colour: tuple[str, str, str] | None
    packed_colour: str | None
    extras: tuple[tuple[str, str, int | None], ...]  # (field, store name, element of a multi-value field)
    intensity: str | None = None  # the field that is the LAS intensity

    def dimensions(self, dtype: np.dtype) -> list[Dimension]:
        """The store dimensions of this map, ``x``, ``y``, ``z`` first."""
        dims = coordinate_dimensions()
        if self.colour or self.packed_colour:
            dims += color_dimensions()
        if self.intensity:
            dims.append(Dimension("intensity", "uint16", "las", f"intensity (source field {self.intensity})",
                                  {"name": "intensity"}))
        for field, name, element in self.extras:
            base = dtype[field].base if element is not None else dtype[field]
            code = base.str.lstrip("<>|=")
            dims.append(Dimension(name, base.name, "extra", f"source field {field}"
                                  + (f"[{element}]" if element is not None else ""),
                                  {"name": name, "type": code, "description": field[:32]}))
        return dims

    def columns(self, records: np.ndarray, grid: Quantization, path: str) -> PartResult:
        """The store columns of ``records``: coordinates on ``grid``, colour, every extra field."""
        xyz = np.stack([np.asarray(records[a], dtype=np.float64) for a in self.xyz], axis=1)
        bad = ~np.isfinite(xyz).all(axis=1)
        if bad.any():
            raise UserError(path, f"{int(bad.sum()):,} points with non-finite coordinates (NaN or inf)")
        cols = grid.quantize(xyz, path)
        if self.colour:
            for c, f in zip(("red", "green", "blue"), self.colour):
                cols[c] = np.clip(np.asarray(records[f]), 0, 65535).astype(np.uint16)
        elif self.packed_colour:
            packed = np.ascontiguousarray(records[self.packed_colour])
            v = packed.view(np.uint32) if packed.dtype.itemsize == 4 else packed.astype(np.uint32)
            for c, shift in (("red", 16), ("green", 8), ("blue", 0)):
                cols[c] = ((v >> shift) & 0xFF).astype(np.uint16)
        if self.intensity:
            cols["intensity"] = np.asarray(records[self.intensity]).astype(np.uint16)
        for field, name, element in self.extras:
            a = records[field]
            cols[name] = np.ascontiguousarray(a[:, element] if element is not None else a)
        return PartResult(cols, {"points": int(len(records))})


def field_map(dtype: np.dtype, path: str) -> FieldMap:
    """The :class:`FieldMap` of a structured record dtype; a clear error without x, y and z."""
    names = list(dtype.names or ())
    lower = {n.lower(): n for n in names}
    missing = [a for a in "xyz" if a not in lower]
    if missing:
        raise UserError(path, f"no {'/'.join(missing)} field: expected point records with x, y and z "
                              f"(fields: {', '.join(names) or 'none'})")
    xyz = (lower["x"], lower["y"], lower["z"])
    used = set(xyz)
    colour = None
    for variant in zip(*COLOUR_NAMES.values()):
        if all(v in lower for v in variant):
            colour = tuple(lower[v] for v in variant)
            used |= set(colour)
            break
    packed = None
    if colour is None:
        packed = next((lower[p] for p in PACKED_COLOUR if p in lower and dtype[lower[p]].itemsize == 4), None)
        if packed:
            used.add(packed)
    intensity = lower.get("intensity")
    if intensity and dtype[intensity].kind == "u" and dtype[intensity].itemsize <= 2:
        used.add(intensity)
    else:
        intensity = None
    taken = {"x", "y", "z", "red", "green", "blue", "point_index"} | LAS_STANDARD
    extras = []
    for n in names:
        if n in used or n.startswith("#$%&~~"):  # PCD padding fields ("_")
            continue
        t = dtype[n]
        if t.kind not in _EXTRA_KINDS and not (t.subdtype and t.base.kind in _EXTRA_KINDS):
            raise UserError(path, f"field {n!r} has type {t}: only numeric scalar fields can be kept")
        if t.subdtype:
            for k in range(int(np.prod(t.shape))):
                name = safe_name(f"{n}_{k}", taken)
                taken.add(name)
                extras.append((n, name, k))
        else:
            name = safe_name(n, taken)
            taken.add(name)
            extras.append((n, name, None))
    return FieldMap(xyz, colour, packed, tuple(extras), intensity)  # type: ignore[arg-type]


class RecordReader(Reader):
    """A file of point records read by row ranges: ``(start, stop, part_points)`` specs, one task per
    ``part_points`` rows when the rows can be entered anywhere (``self.mapped``: a memory-mapped binary file),
    else one task for the whole file that cuts it into parts.  Subclasses set ``count`` and ``mapped``."""

    count: int
    mapped: bool = False

    def plan(self, part_points: int) -> list[Any]:
        if self.mapped:
            return [(a, min(a + part_points, self.count), part_points) for a in range(0, self.count, part_points)]
        return [(0, self.count, part_points)]

    def parts_of(self, spec: Any) -> int:
        start, stop, part_points = spec
        return -(-(stop - start) // part_points)
