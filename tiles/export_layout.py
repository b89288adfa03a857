"""Where every store array goes in the exported LAS point records, and packing a part's columns into them.

The point format is the source's (``meta.las["point_format"]``), 7 for stores
without a LAS source; stored LAS fields go back to their fields, results and
ground truth become extra bytes (a ``classification`` result fills the LAS
field as ``64 + code``, the user-definable LAS 1.4 range, and the extra
dimension ``element_class`` as the code 0-12).  A legacy source format (0-5)
is raised to its LAS 1.4 twin when there is a classification result: its
5-bit field cannot hold 64-76.  The rules: docs/design/tiles.md, "What goes where".
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import laspy
import numpy as np

from tiles.classes import LAS_CLASS_OFFSET
from tiles.errors import UserError
from tiles.ingest.lasformat import bit_shift, standard_names, subfields
from tiles.store import TileStore

#: LAS extra-bytes names and descriptions are at most 32 bytes.
_NAME_LEN = 32
#: The LAS 1.4 point format that holds everything of a legacy one (0-5): 64-76 need a full classification byte.
LAS14_TWIN = {0: 6, 1: 6, 2: 7, 3: 7, 4: 9, 5: 10}
#: The point format of a COPC file for each other format (COPC takes 6, 7 or 8 only; wave packet fields, of
#: formats 4, 5, 9 and 10, become extra bytes).
COPC_TWIN = {0: 6, 1: 6, 2: 7, 3: 7, 4: 6, 5: 7, 6: 6, 7: 7, 8: 8, 9: 6, 10: 8}
#: Bumped when the exported file's layout changes (a resumed run then rewrites ``points.laz``).
LAYOUT_VERSION = 2
#: Degrees per unit of the LAS 1.4 ``scan_angle`` field (legacy ``scan_angle_rank`` is whole degrees).
_SCAN_ANGLE_UNIT = 0.006


@dataclass
class Column:
    """Where one store array goes in the LAS record."""

    store: str
    how: str  # "field", "bits", "component", "angle" (legacy scan_angle_rank into scan_angle)
    target: str  # LAS field (or packed field for bits)
    mask: int = 0
    component: int = 0
    scale_colour: bool = False
    add: int = 0  # added to the value (the classification result: LAS_CLASS_OFFSET)


@dataclass
class Layout:
    """The output point format, its extra-bytes records and the store-array-to-field mapping (pickles small)."""

    point_format: int
    extra: list[dict[str, Any]] = field(default_factory=list)
    columns: list[Column] = field(default_factory=list)
    class_lookup: bool = False  # the classification field holds 64 + class code: write the lookup VLR

    def point_format_obj(self) -> laspy.PointFormat:
        """The laspy point format with the extra-bytes records."""
        pf = laspy.PointFormat(self.point_format)
        for e in self.extra:
            pf.add_extra_dimension(laspy.ExtraBytesParams(
                e["name"], e["type"], description=e.get("description", "")[:_NAME_LEN],
                offsets=e.get("offsets"), scales=e.get("scales"), no_data=e.get("no_data")))
        return pf

    @property
    def store_names(self) -> list[str]:
        """The store arrays an export reads: the coordinates, ``point_index`` and every column's."""
        return ["x", "y", "z", "point_index"] + [c.store for c in self.columns]


def plan_layout(store: TileStore, point_format: int | None = None, copc: bool = False) -> Layout:
    """Decide the point format and where every store array goes (see docs/design/tiles.md, "What goes where");
    ``copc``: a format COPC takes (6, 7 or 8, :data:`COPC_TWIN`)."""
    meta = store.meta
    has_result_class = any(d.name == "classification" and d.kind == "result" for d in meta.dimensions)
    fmt, raised = choose_format(int((meta.las or {}).get("point_format", 7)), point_format, has_result_class, copc)
    std = set(standard_names(fmt))
    subs = subfields(fmt)
    scale_colour = meta.las is None and meta.color_depth == 8
    layout = Layout(fmt)
    used: set[str] = set(std) | {"X", "Y", "Z"}
    std_taken: set[str] = set()
    groups: dict[str, str] = {}  # extra-bytes record name -> output name, for multi-element records

    def add_extra(name: str, dtype: str, description: str, record: dict[str, Any] | None) -> str:
        out, k = name[:_NAME_LEN], 1
        while out in used:
            k += 1
            out = f"{name[:_NAME_LEN - 4]}_{k}"
        used.add(out)
        rec = {"name": out, "type": dtype, "description": description[:_NAME_LEN]}
        for key in ("scales", "offsets", "no_data"):
            if record and record.get(key) is not None:
                rec[key] = record[key]
        layout.extra.append(rec)
        return out

    # results first, so that they keep their own names
    for d in sorted(meta.dimensions, key=lambda d: 0 if d.kind == "result" else 1):
        if d.kind in ("coordinate", "index"):
            continue
        las = d.las or {}
        lname = las.get("name", d.name)
        plain = np.dtype(d.dtype).str[1:]
        if d.kind == "result":
            if d.name == "classification" and "classification" in std:
                std_taken.add("classification")
                col = _std_column(d.name, "classification", subs)
                col.add = LAS_CLASS_OFFSET
                layout.columns.append(col)
                layout.columns.append(Column(d.name, "field", add_extra("element_class", "u1",
                                                                        "S3DIS class 0 ceiling..12 clutter", None)))
                layout.class_lookup = True
            else:
                layout.columns.append(Column(d.name, "field", add_extra(d.name, plain, d.description or d.name,
                                                                        None)))
        elif d.kind == "las":
            if lname == "classification" and has_result_class:
                target = add_extra("source_classification", plain, "classification of the source", None)
                layout.columns.append(Column(d.name, "field", target))
            elif raised and lname == "scan_angle_rank" and "scan_angle" not in std_taken:
                std_taken.add("scan_angle")  # a legacy source raised to its LAS 1.4 twin
                layout.columns.append(Column(d.name, "angle", "scan_angle"))
            elif lname in std and lname not in std_taken:
                std_taken.add(lname)
                col = _std_column(d.name, lname, subs)
                col.scale_colour = scale_colour and lname in ("red", "green", "blue", "nir")
                layout.columns.append(col)
            else:  # a standard field this point format lacks
                layout.columns.append(Column(d.name, "field", add_extra(lname, plain, d.description or lname,
                                                                        None)))
        elif las.get("component") is not None:  # one element of a multi-element extra-bytes record
            if lname not in groups:
                groups[lname] = add_extra(lname, las.get("type", plain), las.get("description", ""), las)
            layout.columns.append(Column(d.name, "component", groups[lname], component=int(las["component"])))
        else:  # extra bytes and ground truth
            target = add_extra(lname, las.get("type") or plain, las.get("description", d.description or lname),
                               las)
            layout.columns.append(Column(d.name, "field", target))
    return layout


def choose_format(source: int, point_format: int | None, has_result_class: bool, copc: bool) -> tuple[int, bool]:
    """The output point format and whether it is a legacy one (0-5) raised to LAS 1.4: ``point_format`` if given,
    else the ``source``'s, raised for a classification result (:data:`LAS14_TWIN`) or COPC (:data:`COPC_TWIN`)."""
    fmt = point_format if point_format is not None else source
    if not 0 <= fmt <= 10:
        raise UserError(None, f"LAS point format must be 0-10, not {fmt}")
    raised = (has_result_class or copc) and fmt in LAS14_TWIN
    if copc:
        if point_format is not None and fmt not in (6, 7, 8):
            raise UserError(None, f"COPC takes point formats 6, 7 and 8, not {fmt}")
        return COPC_TWIN[fmt], raised
    if raised:
        if point_format is not None:
            raise UserError(None, f"the classes (LAS codes {LAS_CLASS_OFFSET}-{LAS_CLASS_OFFSET + 12}) do not fit "
                                  f"the 5-bit classification of point format {fmt}: export to a format >= 6")
        return LAS14_TWIN[fmt], raised
    return fmt, raised


def _std_column(store_name: str, lname: str, subs: dict[str, tuple[str, int]]) -> Column:
    if lname in subs:
        packed, mask = subs[lname]
        return Column(store_name, "bits", packed, mask=mask)
    return Column(store_name, "field", lname)


#: Bytes of records packed at a time by :func:`pack_part`: every field of a block is written while the block is in
#: the cache (a field written over a whole tile streams all of its records through memory once per field).
PACK_BLOCK_BYTES = 1 << 20


def pack_part(cols: dict[str, np.ndarray], layout: Layout) -> np.ndarray:
    """LAS point records (a structured array of the layout's point format) from a part's columns."""
    pf = layout.point_format_obj()
    n = len(cols["x"])
    arr = np.zeros(n, dtype=pf.dtype())
    # (target, values, or into the field, component), in the layout's order, every value converted whole
    ops: list[tuple[str, np.ndarray, bool, int | None]] = [("X", cols["x"], False, None), ("Y", cols["y"], False, None),
                                                          ("Z", cols["z"], False, None)]
    for c in layout.columns:
        v = cols[c.store]
        if c.scale_colour:
            v = v.astype(np.uint16) * np.uint16(257)
        if c.add:
            v = v.astype(np.int64) + c.add
        if c.how == "angle":
            v = np.round(v.astype(np.float64) / _SCAN_ANGLE_UNIT).astype(np.int16)
        if c.how == "bits":
            top = c.mask >> bit_shift(c.mask)
            if len(v) and (v.min() < 0 or v.max() > top):
                raise UserError(None, f"{c.store} values up to {int(v.max())} do not fit the {top.bit_length()}-bit "
                                      f"LAS field of point format {layout.point_format}: export to a format >= 6")
            ops.append((c.target, (v.astype(np.uint8) << bit_shift(c.mask)) & c.mask, True, None))
        else:
            ops.append((c.target, v, False, c.component if c.how == "component" else None))
    step = max(1, PACK_BLOCK_BYTES // arr.dtype.itemsize)
    for s in range(0, n, step):
        block = arr[s:s + step]
        for target, v, bits, component in ops:
            if bits:
                block[target] |= v[s:s + step]
            elif component is not None:
                block[target][:, component] = v[s:s + step]
            else:
                block[target] = v[s:s + step]
    return arr


def take_records(records: np.ndarray, index: np.ndarray) -> np.ndarray:
    """``records[index]`` for LAS records, moved as plain bytes: numpy gathers a record of named fields field by
    field, several times slower than one fixed-size byte record (the same bytes either way)."""
    rec = np.ascontiguousarray(records)
    return np.take(rec.view(np.dtype((np.void, rec.dtype.itemsize))), index).view(rec.dtype)


def join_records(parts: list[np.ndarray], dtype: np.dtype) -> np.ndarray:
    """The records of ``parts`` (arrays of ``dtype``, or bytes of its records) one after another, moved as plain
    bytes."""
    void = np.dtype((np.void, dtype.itemsize))
    if not parts:
        return np.zeros(0, dtype=dtype)
    return np.concatenate([np.frombuffer(p, dtype=void) if isinstance(p, (bytes, bytearray, memoryview))
                           else np.ascontiguousarray(p).view(void) for p in parts]).view(dtype)
